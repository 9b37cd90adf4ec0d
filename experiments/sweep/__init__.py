"""Experiment sweeps: grids of cells from a TOML config, run locally or on Dask,
resumable, reported as CSV, markdown tables and figures.

Modules: :mod:`.config` (TOML -> validated dataclasses), :mod:`.rules` (which
combinations make cells), :mod:`.tasks` (settings -> task objects), :mod:`.cells`
(expansion, keys, running and storing one cell), :mod:`.backends` (serial, local pool,
Dask), :mod:`.report` and :mod:`.plots` (tables and figures), :mod:`.cli` (commands).
"""

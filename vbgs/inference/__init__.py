"""Conjugate inference for the Gaussian mixture: the exponential-family math
(:mod:`~vbgs.inference.expfam`), the mixture and its CAVI update (:mod:`~vbgs.inference.model`),
the E-step paths (dense; sparse with KD-tree :mod:`~vbgs.inference.candidates` or device
:mod:`~vbgs.inference.grid`), the compiled stepper of a stream, growth from empty slots,
re-seeding, the prior's length scale, the streaming bound and sharding over devices.

Nothing here renders or reads files; the modules are imported one by one (importing the
package imports none of them, so a start-up pays only for what it uses).
"""

"""``main`` prints one line only for the project's own input errors (ValueError and its
subclasses, files it cannot read or write, a missing optional dependency); a programming
error keeps its traceback."""

import pytest

import experiments.run as run


def _command_raising(monkeypatch, err):
    def fails(args):
        raise err

    add = run.COMMANDS["check"][0]
    monkeypatch.setitem(run.COMMANDS, "check", (add, fails))


@pytest.mark.parametrize("err", [ValueError("bad --size"), FileNotFoundError("no such file"),
                                 ImportError("onnxruntime is not installed")])
def test_input_errors_are_one_line(monkeypatch, capsys, err):
    _command_raising(monkeypatch, err)
    assert run.main(["check", "--scene", "x"]) == 2
    assert capsys.readouterr().err.strip() == f"error: {err}"


@pytest.mark.parametrize("err", [TypeError("unsupported operand"), AttributeError("no attr"),
                                 KeyError("k")])
def test_programming_errors_keep_their_traceback(monkeypatch, err):
    _command_raising(monkeypatch, err)
    with pytest.raises(type(err)):
        run.main(["check", "--scene", "x"])

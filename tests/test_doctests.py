"""The ``>>>`` examples in the docstrings are checked: those of the conventions modules
(values worked out by hand: they document the frames and metrics, and fail when either
drifts), and every other module's (the same as ``pytest --doctest-modules relight``)."""
import doctest
import importlib
import pkgutil

import pytest

import relight
import relight.frames
import relight.metrics

MODULES = sorted(m.name for m in pkgutil.walk_packages(relight.__path__, "relight.")
                 if m.name != "relight.__main__") + ["relight"]


@pytest.mark.parametrize("module", [relight.frames, relight.metrics], ids=lambda m: m.__name__)
def test_docstring_examples(module):
    result = doctest.testmod(module, optionflags=doctest.ELLIPSIS, verbose=False)
    assert result.attempted >= 10, f"{module.__name__}: too few examples ({result.attempted})"
    assert result.failed == 0, f"{module.__name__}: {result.failed} doctest failures (see output above)"


@pytest.mark.parametrize("name", MODULES)
def test_every_modules_examples(name):
    module = importlib.import_module(name)
    result = doctest.testmod(module, optionflags=doctest.ELLIPSIS, verbose=False)
    assert result.failed == 0, f"{name}: {result.failed} doctest failures (see output above)"


def test_the_public_face_has_examples():
    # each function of the top-level API carries at least one example
    for name in ("generate", "load_scene", "render_spec", "load_model", "predict_arrays", "predict_files",
                 "compare_predictions", "invert", "read_manifest", "read_predictions", "write_predictions"):
        doc = getattr(relight, name).__doc__ or ""
        assert ">>>" in doc, f"relight.{name} has no example"
        assert "Args:" in doc and "Returns:" in doc, f"relight.{name} has no Args/Returns block"

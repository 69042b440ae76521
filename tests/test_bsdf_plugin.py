"""The roughdiffuse plugin class lives at module level and registers on import, as
Mitsuba's own Python plugins do; importing it before a variant is set touches nothing."""
import subprocess
import sys
import textwrap


def _run(code: str) -> str:
    out = subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True,
                         text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    return out.stdout.strip()


def test_import_without_variant_leaves_mitsuba_alone():
    out = _run("""
        import sys
        import relight.scene.bsdf as b
        print(b.RoughDiffuse is None, "mitsuba" in sys.modules, "drjit" in sys.modules)
    """)
    assert out == "True False False"


def test_registered_on_import_with_variant_set():
    # no register() call: importing the module with a variant set defines and registers it
    out = _run("""
        from relight import backend
        mi = backend.init(threads=1)
        from relight.scene.bsdf import RoughDiffuse, PLUGIN
        b = mi.load_dict({"type": PLUGIN, "roughness": 0.25})
        print(type(b).__name__, RoughDiffuse.__module__, isinstance(b, RoughDiffuse), b.to_string())
    """)
    assert out == "RoughDiffuse relight.scene.bsdf True RoughDiffuse[roughness=[0.25]]"


def test_register_after_late_import_defines_the_class():
    out = _run("""
        import relight.scene.bsdf as b
        assert b.RoughDiffuse is None
        b.register()
        b.register()   # idempotent
        from relight import backend
        mi = backend.mitsuba()
        print(b.RoughDiffuse.__name__, type(mi.load_dict({"type": "roughdiffuse"})).__name__)
    """)
    assert out == "RoughDiffuse RoughDiffuse"


def test_docstring_has_parameter_table():
    import relight.scene.bsdf as b
    for name in ("reflectance", "roughness", "Parameter", "Default"):
        assert name in b.__doc__

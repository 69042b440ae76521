"""Rough diffuse BSDF (Oren-Nayar, Fujii's form, as in Blender Cycles' Diffuse BSDF).

The paper rendered SID2 with Blender, whose Diffuse BSDF has a roughness that turns
Lambert into Oren-Nayar. Mitsuba 3.9 ships no Oren-Nayar plugin, so this module
registers ``roughdiffuse`` written in Python; in JIT variants it is traced into the
same kernels as the built-in plugins.

BRDF (Fujii, "A tiny improvement of Oren-Nayar reflectance model", 2012; the form of
Cycles' ``bsdf_oren_nayar``)::

    f(wi, wo) = rho * (A + B * s / t),   s = <wi, wo> - cos_i cos_o,
    t = max(cos_i, cos_o) if s > 0 else 1,
    A = 1 / (pi + (pi/2 - 2/3) sigma),   B = sigma * A,   sigma = roughness in [0, 1].

With ``roughness = 0`` it is exactly Lambert (rho / pi). Sampling is cosine-weighted,
like Mitsuba's ``diffuse``, so a render with roughness 0 matches ``diffuse`` sample
for sample.

Plugin ``roughdiffuse`` (class :class:`RoughDiffuse`), parameters:

=============  ===================  =======  ==========================================
Parameter      Type                 Default  Meaning
=============  ===================  =======  ==========================================
reflectance    spectrum or texture  0.5      diffuse albedo rho (linear RGB); exposed
                                             as ``reflectance`` (differentiable)
roughness      float in [0, 1]      0.5      Oren-Nayar sigma; 0 is Lambert; exposed as
                                             ``roughness`` (not differentiable; changing
                                             it does not recompile kernels)
=============  ===================  =======  ==========================================

Flags: diffuse reflection, front side only (back-facing directions give zero).

Like Mitsuba's own Python plugins, the class is defined and registered when this
module is imported with a Mitsuba variant already set (``mi.set_variant`` or
:func:`relight.backend.init`); imported before that (e.g. by a command's ``--help``)
the module loads without touching Mitsuba, ``RoughDiffuse`` is ``None``, and
:func:`register` defines and registers the class for the current variant (again after
a variant switch)::

    from relight import backend
    from relight.scene import bsdf
    mi = backend.init()
    bsdf.register()
    b = mi.load_dict({"type": "roughdiffuse", "roughness": 0.3,
                      "reflectance": {"type": "rgb", "value": [0.6, 0.5, 0.4]}})
"""
from __future__ import annotations

__all__ = [
    "PLUGIN", "RoughDiffuse", "register",
]

import importlib
import math
import sys
import threading

from relight import backend

PLUGIN = "roughdiffuse"


def _variant_mitsuba():
    """The ``mitsuba`` module if it is imported with a variant set, else None. Never
    imports or initialises Mitsuba (the backend chooses libLLVM before that)."""
    mod = sys.modules.get("mitsuba")
    if mod is None or "drjit" not in sys.modules:
        return None
    try:
        return mod if mod.variant() else None
    except Exception:  # noqa: BLE001 - a half-initialised Mitsuba means "not ready"
        return None


_lock = globals().get("_lock") or threading.Lock()   # kept across reloads
mi = _variant_mitsuba()
RoughDiffuse = None       # the plugin class, defined below when a variant is set
_registered_variant = None  # the variant RoughDiffuse was defined and registered for

if mi is not None:
    import drjit as dr

    class RoughDiffuse(mi.BSDF):  # noqa: F811 - defined only with a variant set
        """Oren-Nayar rough diffuse reflection (Mitsuba plugin ``roughdiffuse``).

        ===========  ===================  =======  =================================
        Parameter    Type                 Default  Meaning
        ===========  ===================  =======  =================================
        reflectance  spectrum or texture  0.5      albedo rho (linear RGB)
        roughness    float in [0, 1]      0.5      Oren-Nayar sigma; 0 is Lambert
        ===========  ===================  =======  =================================
        """

        def __init__(self, props):
            mi.BSDF.__init__(self, props)
            self.reflectance = props.get("reflectance", mi.ScalarColor3f(0.5))
            if not isinstance(self.reflectance, mi.Texture):
                self.reflectance = mi.load_dict({"type": "rgb", "value": self.reflectance})
            roughness = float(props.get("roughness", 0.5))
            if not 0.0 <= roughness <= 1.0:
                raise ValueError(f"roughdiffuse: roughness must be in [0, 1], got {roughness}")
            self.roughness = mi.Float(roughness)
            dr.make_opaque(self.roughness)  # a new value must not recompile the kernel
            self.m_flags = mi.BSDFFlags.DiffuseReflection | mi.BSDFFlags.FrontSide
            self.m_components = [self.m_flags]

        def _f(self, si, wo, active):
            """BRDF times cos_o, for local directions (cos_i, cos_o > 0 checked by callers)."""
            wi = si.wi
            cos_i = mi.Frame3f.cos_theta(wi)
            cos_o = mi.Frame3f.cos_theta(wo)
            sigma = dr.clip(self.roughness, 0.0, 1.0)
            a = 1.0 / (math.pi + (0.5 * math.pi - 2.0 / 3.0) * sigma)
            b = sigma * a
            s = dr.dot(wi, wo) - cos_i * cos_o
            t = dr.select(s > 0.0, dr.maximum(cos_i, cos_o), 1.0)
            rho = self.reflectance.eval(si, active)
            return rho * (a + b * s / t) * cos_o

        def sample(self, ctx, si, sample1, sample2, active=True):
            cos_i = mi.Frame3f.cos_theta(si.wi)
            active = active & (cos_i > 0.0)
            bs = mi.BSDFSample3f()
            bs.wo = mi.warp.square_to_cosine_hemisphere(sample2)
            bs.pdf = mi.warp.square_to_cosine_hemisphere_pdf(bs.wo)
            bs.eta = 1.0
            bs.sampled_type = mi.UInt32(+mi.BSDFFlags.DiffuseReflection)
            bs.sampled_component = mi.UInt32(0)
            active = active & (bs.pdf > 0.0) & ctx.is_enabled(mi.BSDFFlags.DiffuseReflection)
            weight = self._f(si, bs.wo, active) / dr.maximum(bs.pdf, 1e-20)
            return bs, dr.select(active, weight, 0.0)

        def eval(self, ctx, si, wo, active=True):
            active = active & (mi.Frame3f.cos_theta(si.wi) > 0.0) & (mi.Frame3f.cos_theta(wo) > 0.0)
            active = active & ctx.is_enabled(mi.BSDFFlags.DiffuseReflection)
            return dr.select(active, self._f(si, wo, active), 0.0)

        def pdf(self, ctx, si, wo, active=True):
            active = active & (mi.Frame3f.cos_theta(si.wi) > 0.0) & (mi.Frame3f.cos_theta(wo) > 0.0)
            return dr.select(active, mi.warp.square_to_cosine_hemisphere_pdf(wo), 0.0)

        def eval_pdf(self, ctx, si, wo, active=True):
            return self.eval(ctx, si, wo, active), self.pdf(ctx, si, wo, active)

        def traverse(self, callback):
            callback.put("reflectance", self.reflectance, mi.ParamFlags.Differentiable)
            callback.put("roughness", self.roughness, mi.ParamFlags.NonDifferentiable)

        def parameters_changed(self, keys=[]):  # noqa: B006 - Mitsuba's signature
            dr.make_opaque(self.roughness)

        def to_string(self):
            return f"RoughDiffuse[roughness={self.roughness}]"

    mi.register_bsdf(PLUGIN, lambda props: RoughDiffuse(props))
    _registered_variant = mi.variant()


def register() -> None:
    """Make ``roughdiffuse`` available in the current variant (idempotent).

    Initialises the backend if needed; when the module was imported before a variant
    was set (or the variant changed since), it is reloaded so that the class above is
    defined and registered for the current variant.
    """
    current = backend.mitsuba().variant()
    with _lock:
        if _registered_variant != current:
            importlib.reload(sys.modules[__name__])

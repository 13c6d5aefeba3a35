"""Position-controller variants, one module each, registered on import.

Adding a variant: a module here (or anywhere) that calls
:func:`register_variant` with a :class:`Variant`, imported by this package
(add it to the list below) or by the user before the variant is named.

:data:`DEFAULT_VARIANT` is the variant flown when none is named: the
paper's proposed controller, PD + LM-FNN.
"""
from .registry import (Variant, initial_axis_state, register_variant, unregister_variant, variant, variant_names,
                       variants)

from . import pd, pd_smc, pd_lm, pd_it2_smc, pd_it2_lm  # noqa: E402,F401  (the paper's three first, in its order)

DEFAULT_VARIANT: str = pd_lm.PD_LM.name

__all__ = ["DEFAULT_VARIANT", "Variant", "initial_axis_state", "register_variant", "unregister_variant", "variant",
           "variant_names", "variants"]

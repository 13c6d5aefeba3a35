"""Every shipped FMU model that draws random numbers declares its seed
parameter as the engine expects it: a whole number in [0, SEED_LIMIT], so
the exporter's limit (``fmu_models.export.variables.SEED_MAX``) and the
engine's (``cosim.limits.SEED_LIMIT``, which bounds the seeds it
derives) cannot drift apart."""
from __future__ import annotations

from cosim.scenario import registry
from cosim.limits import SEED_LIMIT
from fmu_models.catalog import MODEL_NAMES, model
from fnn_controller.controller_fmu import controller_model, fmu_identifier
from fnn_controller.split import INNER_IDENTIFIER, inner_model, outer_identifier, outer_model
from fnn_controller.variants import variant_names


def _shipped_models():
    """The FMU models the application registers, by identifier."""
    models = {name: model(name) for name in MODEL_NAMES}
    for name in variant_names():
        models[fmu_identifier(name)] = controller_model(name)
        models[outer_identifier(name)] = outer_model(name)
    models[INNER_IDENTIFIER] = inner_model()
    return models


def test_these_are_every_registered_fmu_model():
    assert set(_shipped_models()) == set(registry.fmu_models())


def test_every_seed_parameter_declares_the_engines_seed_limit():
    seeded = 0
    for identifier, m in _shipped_models().items():
        if m.sampled is None or m.sampled.seed is None:
            continue
        seed = m.variable(m.sampled.seed)
        assert (seed.causality, seed.integer, seed.min, seed.max) == ("parameter", True, 0.0, SEED_LIMIT), identifier
        seeded += 1
    assert seeded >= 3 + 2 * len(variant_names())  # the sensor links, every controller whole and outer

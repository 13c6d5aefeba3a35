"""A sampled-data FMU declares its period parameter in its modelDescription,
as the standard lets a tool annotate it: FMI 2.0 ``VendorAnnotations/Tool``,
FMI 3.0 ``Annotations/Annotation type=...``, each holding
``<SampledData periodParameter="dt"/>``; a continuous FMU declares none.
The engine reads it (``FmuComponent.sample_period``). fmpy's validator
finding no problem in these FMUs is tested with each model."""
from __future__ import annotations

import zipfile

import pytest
from lxml import etree

import fnn_controller as fc
from cosim.fmi.fmu import FmuComponent
from fmu_models.catalog import MODELS
from tests.catalog_fmus import catalog_fmu
from fnn_controller.controller_fmu import controller_model
from fnn_controller.fmu_names import fmu_identifier

# the catalog's models and each controller variant's, by identifier: a controller's CasADi model is built by
# its tests, not by every test process's collection (0.3-0.4 CPU-s a process)
MODELS_AND_CONTROLLERS = [*MODELS, *(pytest.param(v, id=fmu_identifier(v)) for v in fc.variant_names())]
WHERE = {2: "VendorAnnotations/Tool[@name='fnn-cosim.sampled-data']/SampledData",
         3: "Annotations/Annotation[@type='fnn-cosim.sampled-data']/SampledData"}


@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("name", MODELS_AND_CONTROLLERS)
def test_a_sampled_data_fmu_declares_its_period_parameter_and_a_continuous_one_nothing(name, version):
    model = MODELS[name] if name in MODELS else controller_model(name)
    path = catalog_fmu(model, version)
    with zipfile.ZipFile(path) as archive:
        root = etree.fromstring(archive.read("modelDescription.xml"))
    declared = [e.get("periodParameter") for e in root.findall(WHERE[version])]
    expected = model.sampled.sample_period if model.sampled is not None else None
    assert expected == "dt" or not model.identifier.startswith("Controller")  # the controllers' period is dt
    assert declared == ([expected] if expected else [])
    if expected is None:  # nothing annotated at all
        assert root.find("VendorAnnotations") is None and root.find("Annotations") is None
    assert FmuComponent(model.identifier, path).sample_period == expected

"""The models, one module each: the variable table and the equations in
CasADi (:class:`fmu_models.export.model.FmuModel`). A new model is one module
here plus its entry in :mod:`fmu_models.catalog`."""

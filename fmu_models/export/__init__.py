"""The exporter: any :class:`~fmu_models.export.model.FmuModel` to FMI 2.0
and FMI 3.0 FMUs. The variable table (``variables``), the five CasADi
functions of a model (``model``), their C code (``codegen``), the
modelDescription (``model_description``), the build and its cache
(``build``), and the generic FMI C layer (``c/``), which knows no model."""

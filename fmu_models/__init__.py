"""Plant models written once in CasADi and exported as FMI 2.0 / 3.0 FMUs."""

__version__ = "0.1.0"

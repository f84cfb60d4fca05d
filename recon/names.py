"""Display names of sensors and methods in tables, plots and reports (the paper's names)."""

#: Names in tables and plots: the paper's names for its two cameras.
NAMES = {"ml-msb": "ML", "te": "TE", "ml": "ML-count", "te+eq12": "TE+dark12", "te+eq13": "TE+dark13"}
#: Methods as the paper names them (``label``); other methods in capitals.
METHOD_NAMES = {"tfp": "TFP", "tfi": "TFI", "spk2imgnet": "Spk2ImgNet", "bsf": "BSF", "mambaspike1": "MambaSpike1",
                "mambaspike": "MambaSpike", "net": "Net"}


def name(sensor: str) -> str:
    """Table name of a sensor: ``ML`` (msb, the paper's), ``TE``, ``ML-count``; else the key in capitals."""
    return NAMES.get(sensor, sensor.upper())


def label(method: str, sensor: str) -> str:
    """Paper-style name, e.g. ``TFP_TE``, ``TFI_ML`` (msb camera), ``BSF_ML-count``, ``Net_TE``."""
    return f"{METHOD_NAMES.get(method, method.upper())}_{name(sensor)}"

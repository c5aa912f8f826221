"""Offline robust-control toolbox: control-oriented models, uncertainty weights, structured
H-infinity tuning, mu analysis, baselines and gain-schedule export."""

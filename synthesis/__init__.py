"""Offline robust-control toolbox: control-oriented models, uncertainty weights, structured
H-infinity tuning, mu analysis, baselines and gain-schedule export.

Library API (see ``synthesis/README.md`` for examples; every public definition outside
``design`` and ``robust`` has a numpydoc docstring, the entry points with doctested
examples): ``mu_blocks.Block`` / ``mu_blocks.BlockStructure``, ``hinfnorm.hinf_norm``,
``mu.mu_bounds`` / ``mu.mu_sweep``, ``mixed_mu.mixed_mu_upper`` / ``mixed_mu.mixed_mu_sweep``
(real and repeated-real blocks, non-square M), ``lft.GeneralizedPlant`` / ``lft.lft``,
``blocks`` (``StaticGain``, ``StateSpaceBlock``, ``PIDBlock``, ``PPIDBlock``,
``ControllerStructure``, ``lft_problem``), ``structured.TuningProblem`` / ``structured.tune``,
``uncertainty.cover``; the paper's design on top: ``loops`` (cascaded P-PID, eq. 8 channel),
``design`` (GS-SHIF and SHIF tunes), ``robustness`` (eq. 12-14), ``baselines`` (LQR),
``export`` (gain files), ``report`` and ``pipeline`` (``vtolftc synth``)."""

"""Fault campaigns: sweep fault envelopes in parallel and map where each controller survives.

``spec`` (TOML spec files), ``scenarios`` (expansion), ``execute`` (one scenario; local pool
and Dask), ``results`` (Parquet parts), ``outcome`` (the survival definition), ``report``
(summary, gates, HTML and PNGs, comparisons); the command line is ``vtolftc.cli.cmd_campaign``.
"""

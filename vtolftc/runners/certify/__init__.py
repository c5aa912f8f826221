"""``vtolftc certify``: an airframe file taken through trim, robust synthesis, the mixed-mu
certificate, the fault-envelope campaign and a SITL mission to one report with gates.

:mod:`.pipeline` runs stages with a cache and gates (stage functions injectable),
:mod:`.stages` holds the real stages, :mod:`.report` writes the self-contained ``report.html``.
"""

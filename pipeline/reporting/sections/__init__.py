"""The report's sections: one module per section, each a function of the report's inputs and
verdicts (and, for figures, the report's :class:`~pipeline.reporting.figure.Figures`) that
returns a frozen dataclass the page renders with ``templates/sections/<name>.html.j2``."""

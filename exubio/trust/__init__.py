"""The trust layer: what a result can be believed for. Label checks (``labels``, ``label_ranges``,
``thorax_check``, ``session_check``, ``missing_markers``), what the marker set determines
(``observability``), figures of merit (``evaluate``), the model-mismatch detector (``mismatch``), the
checks and the verdict (``quality``, ``assess``). Typed results in, a verdict out; no solver runs here."""

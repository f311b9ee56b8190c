"""The trust layer: what a result can be believed for. Label checks (``labels``, with its parts
``label_distances``, ``label_expectations``, ``label_chains``, ``label_swaps``; ``label_ranges``,
``thorax_check``, ``session_check``, ``missing_markers``), what the marker set determines
(``observability``), figures of merit (``evaluate``), the model-mismatch detector (``mismatch``), the
checks and the verdict (``quality``, ``assess``). Typed results in, a verdict out; no solver runs
here. What is known of a model and protocol alone (the structural angle status, the label
expectations) is held by their binding (exubio.protocol.bind), not cached here."""

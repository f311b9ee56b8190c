"""The protocol layer: a marker set's YAML loaded, checked and bound to a model (``load``), and a
trial's labels matched to it (``labels``)."""

"""The model layer: loading a model YAML (``load``), the numpy kinematics (``kinematics``), the ISB
anatomical frames (``anatomy``), joint angles in published definitions (``angles``,
``frame_definitions``) and the coordinates' ranges (``ranges``). Pure numpy; no solver, no files
beyond the model YAML."""

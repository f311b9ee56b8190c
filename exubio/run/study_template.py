"""The study file ``exubio study --template`` prints: every key exubio.run.study reads, explained."""

STUDY_TEMPLATE = """\
# An exubio study file: exubio study study.yaml --out results/   (paths are relative to this file;
# a key marked optional may go). Each trial's results: results/<subject>/<session>/<trial>/.
schema_version: 1
name: shoulder study                # optional
methods: [pf, ls]                   # optional (default [pf, ls]); a session may override
report: true                        # optional: the reports, each trial's PDF/PNG and the study's PDF (default true)
signs: isb                          # optional: isb (raw ISB angles) or clinical (elevation positive); default: each protocol's signs key, else isb
sessions:
  - subject: S01
    session: day1                   # optional (default: s1, s2, ... in order, per subject)
    protocol: upper_limb_21         # optional: a shipped protocol by name, or a YAML file (default upper_limb_21)
    model: upper_extremity          # optional: a shipped model by name, or a YAML file (default: the generic model)
    static: S01/static.c3d          # optional: calibrate the session's model on this static trial first
    functional: S01/move.c3d        # optional, with static: a movement trial for a SCoRE glenohumeral centre
    scapula_trial: S01/raise.c3d    # optional (or a list), with static: the thorax ellipsoid through its scapula postures
    trials: ["S01/task_*.c3d"]      # globs: the session's trials
    relabel: {RADIUS: ULNA, ULNA: RADIUS}        # optional: read these labels as others in every trial, the static too
    static_relabel: {MET2: MET5, MET5: MET2}     # optional: the static only (replaces relabel for it)
    trial_relabel:                  # optional: per trial file name, for that trial only (replaces relabel for it)
      task_03.c3d: {EPI_lat: EPI_med, EPI_med: EPI_lat}
    tasks: {task_03.c3d: drinking}  # optional: per trial file name, its task in angles.parquet (default: the file's stem)
    body_mass_kg: 72.5              # optional: the joint moments too (kg; moments.parquet; or every session: --body-mass)
    hand_load_kg: 1.0               # optional, with body_mass_kg: a mass held in the hand (kg)
  - subject: S02                    # a session without a static trial
    static_frames: "0:50"           # optional: each trial calibrated on these frames of its own (0-based, end excluded)
    trials: ["S02/*.trc"]
"""
"""A study file with every key, as ``exubio study --template`` prints it (a test loads it)."""

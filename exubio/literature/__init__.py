"""Published in vivo shoulder kinematics: the reference data (``reference``), a corridor of study
means in one definition (``corridor``) and the like-for-like comparison (``invivo``)."""

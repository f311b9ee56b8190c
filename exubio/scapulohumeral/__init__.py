"""The scapulohumeral rhythm: scapulothoracic (ST), sternoclavicular (SC) and glenohumeral (GH)
angles against humerothoracic (HT) elevation, raising and lowering apart.

* ``exubio.scapulohumeral.table``: a trial's rhythm (its phases, cycles, each angle's value, standard
  uncertainty and status per frame), resampled on HT elevation, and the mean and SD of a subject's
  trials and of a group of subjects;
* ``exubio.scapulohumeral.reference``: the in vivo corridor of the published studies (exubio/data) in the
  same frames and sequences as the trial's angles, for the plane of the trial's raising;
* ``exubio.scapulohumeral.files``: the same read from the files of ``exubio reconstruct`` and ``exubio
  study`` (no solver: the report draws from here).
"""

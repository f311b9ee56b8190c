"""The run layer: one trial through preparation, a method and the trust checks (``pipeline``), a
session with its static (``session``), one trial as a job (``job``), a study over a pool or Dask
(``study``), live reconstruction from a marker stream (``live``)."""

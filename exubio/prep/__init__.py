"""The preparation layer: a read trial turned into the targets a method tracks (``thorax``: the ISB
thorax frame; ``filtering``: gaps, the low-pass filter and its cut-offs; ``targets``: splines and
the whole chain, gaps kept as NaN)."""

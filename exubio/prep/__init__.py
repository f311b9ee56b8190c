"""The preparation layer: a read trial turned into the targets a method tracks (thorax frame,
low-pass filter, splines, gaps kept as NaN)."""

"""Bone truth: readers of bone-referenced data and the comparison of a reconstruction with bone."""

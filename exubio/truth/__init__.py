"""Bone truth: readers of bone-referenced shoulder data and what exubio's results are judged
against with them (``locator``: scapula landmarks measured by a scapula locator)."""

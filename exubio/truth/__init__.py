"""Bone truth: readers of bone-referenced data (the ISB soft-tissue-artefact data-sharing format, a
scapula locator's landmarks), the comparison of a reconstruction with bone, the scapula calibrations
judged against the locator, and the soft-tissue-artefact amplitude fitted on bone pins."""

"""Simulated trials with a known truth: shoulder rhythm, motion, soft-tissue artefact, noise
(``simulate``) and perturbed subject models (``perturb``)."""

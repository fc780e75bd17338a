"""The fused pre-flight engine's compiled stages (issue 16); see ``rt.preflight.stages``."""

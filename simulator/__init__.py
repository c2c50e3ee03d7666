"""impactlab.simulator: a simulated steel frame and a simulated SigLab-like analyser."""

"""gridcost experiments: one CLI (`python -m experiments.run <target>`), one module per paper artefact."""

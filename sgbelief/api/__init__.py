"""The public wiring of sgbelief: where the reference layers meet the private fast engines.

The model (:mod:`sgbelief.graph`), the evidence and calibration layers and the fusion operators
(:mod:`sgbelief.fusion`) hold the paper's equations and never import :mod:`sgbelief._fast`.
This package sits above both and chooses an engine explicitly: ``engine="fast"`` (the default of
the public entry points) or ``engine="reference"`` (the named steps, for reading and testing).
"""

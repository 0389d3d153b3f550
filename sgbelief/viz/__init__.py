"""Pictures of a belief map: a top-down view (matplotlib), a belief trace per element, and
rerun logging.

The modules read the model (:mod:`sgbelief.graph`) and nothing above it, so the evaluation
harness, the adapters and the command line may all draw with them:

- :mod:`sgbelief.viz.map_state`: what a map shows (each object's footprint, its committed label
  and probability, the refused claims and where they were made), no drawing library needed;
- :mod:`sgbelief.viz.trace`: one (element, predicate) belief over time, read from its provenance;
- :mod:`sgbelief.viz.style`: the colours and markers both drawing back ends share;
- :mod:`sgbelief.viz.map_figure`, :mod:`sgbelief.viz.trace_figure`: the matplotlib figures
  (``sgbelief show``);
- :mod:`sgbelief.viz.rerun_log`: the same state logged into a rerun recording (``sgbelief record``,
  ConceptGraphs per-frame logging; the optional extra ``sgbelief[rerun]``).

matplotlib and rerun are imported only inside the functions that draw or log.
"""

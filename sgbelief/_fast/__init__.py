"""Private: the fast engines of sgbelief (nothing here is public API).

Every module here computes exactly what a reference in the layers below computes, faster: the
fused streaming loops of the operators (:mod:`~sgbelief._fast.baselines`,
:mod:`~sgbelief._fast.calibrated`), the batched wave engine of the pair-local baselines
(:mod:`~sgbelief._fast.batched`) and the cyclic-GC settings of long replays and loads
(:mod:`~sgbelief._fast.gc`). Each is proven identical to its reference by hypothesis tests, and
the measurements behind its shape are in ``docs/performance.md``.

The rules of the package:

- it may import the model, evidence, calibration and fusion layers and read or write their
  private state (that is what makes it fast); nothing in those layers imports it;
- it is chosen explicitly, by the public wiring (:mod:`sgbelief.api`, e.g.
  ``sgbelief.make_operator(name, ..., engine="fast")``) or by a caller that asks for it
  (``sgbelief replay --engine batched``), never by inspecting an object's type or overrides;
- this ``__init__`` imports nothing, so ``import sgbelief._fast.gc`` stays cheap.
"""

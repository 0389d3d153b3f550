"""Private fast paths of sgbelief: each one observably identical to a reference in the public
layers, proven so by hypothesis tests, and chosen explicitly by :mod:`sgbelief.api`.

Nothing below :mod:`sgbelief.api` imports this package; its modules may touch the private state
of the reference layers they speed up. See ``docs/performance.md``.
"""

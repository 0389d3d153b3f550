"""Dawid–Skene: a detector's reliability learned from agreement between its claims, without ground truth.

Dawid & Skene (1979), *Maximum likelihood estimation of observer error-rates using the EM
algorithm*. Each task (a map element v) has a latent class z_v; each observation o of v is a label
l_o given by a worker w_o (here: a claim's detector context and confidence bin, or the geometric
channel), drawn from the worker's confusion row::

    P(z_v = z)                      = pi_z
    P(l_o = l | z_v = z, w_o = w)   = theta_w[z, l]
    P(z_v = z | observations of v)  ∝ pi_z  prod_o theta_{w_o}[z, l_o]          (E-step)

and EM alternates the posterior q_v(z) above with the closed-form maximisation
pi_z = mean_v q_v(z), theta_w[z, l] ∝ lambda + sum_{o: w_o = w, l_o = l} q_{v_o}(z) (M-step,
``smoothing`` lambda a symmetric Dirichlet pseudo-count; 0 is plain maximum likelihood).

Two differences from the textbook model, both optional:

* The latent classes need not be the labels. A worker's label space is the union of every label
  seen (claims name predicates, the geometric channel names its own classes such as
  ``otherprop``), and ``none_class=True`` adds a latent class "none of these" for elements that are
  none of the claimed classes: clutter on which stray detections land. Its confusion row is learned
  like any other: claims on such elements are few, scattered over classes, and low in confidence.
* ``weights``: an observation may count fractionally (a claim's targeting mass T(v)).

One extension, ``emission="dirichlet_multinomial"``: the textbook model takes every observation
of a task as independent given its class, so ten claims of ``bed`` on one object are ten times
the evidence of one. A detector that mistakes an object for a bed does so again in the next frame
(and a segmenter that mislabels an object keeps mislabelling it), so its errors on one task are
correlated. With this emission the counts n_vw (labels worker w gave task v) are
Dirichlet-multinomial around the worker's confusion row, with a per-worker concentration s_w::

    P(n_vw | z_v = z) = DM(n_vw | s_w theta_w[z])                                  (overdispersed emission)
    log q_v(z) = log pi_z + sum_{w, l: n_vwl > 0} [lnG(n_vwl + s_w theta_w[z, l]) - lnG(s_w theta_w[z, l])] + c_v

(:func:`dirichlet_multinomial_cells`; c_v does not depend on z). s_w -> inf is the independent
model (the bracket tends to n log(s theta), whose log s part is the same for every z); a small s_w
makes an object's repeated labels count little more than its distinct ones. theta and pi keep the
closed-form M-step above (the Dirichlet's mean). At iterations 2, 4, 8, 16, ... each s_w becomes
the value of :data:`CONCENTRATIONS` that maximises the expected complete-data log-likelihood
Q_w(s) = sum_v [sum_z q_v(z) sum_l (lnG(n_vwl + s theta) - lnG(s theta)) + lnG(s) - lnG(s + N_vw)]
(:func:`dirichlet_multinomial_log_likelihood`), so the correlation is learned from the map like the
confusions: how much more an object's labels agree with each other than the confusion rows explain.
The first iteration is the independent model's (its posterior is the initial vote, not a fitted
model's, and s chosen on it is far from the fitted one); the choice is not repeated every iteration
because it evaluates every cell once per grid value and s settles at once (docs/performance.md).

The estimator has crowd-kit's shape (``fit`` on a long table, fitted state with a trailing
underscore: ``priors_``, ``errors_``, ``probas_``); with ``none_class=False``, ``smoothing=0``
and majority-vote initialisation it is crowd-kit's ``DawidSkene`` (``tests/test_dawid_skene.py``
checks that on a seeded stream).
"""

from __future__ import annotations

from collections.abc import Collection, Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray
from scipy import sparse
from scipy.special import gammaln

__all__ = ["CONCENTRATIONS", "DawidSkene", "NONE_CLASS", "dirichlet_multinomial_cells",
           "dirichlet_multinomial_log_likelihood"]

#: the name of the latent class "none of the claimed classes"
NONE_CLASS = "<none>"

_EPS = 1e-12

#: the concentrations a worker's Dirichlet is chosen among (``emission="dirichlet_multinomial"``),
#: largest first so that a tie keeps the independent model (inf)
CONCENTRATIONS = (np.inf, 256.0, 128.0, 64.0, 32.0, 16.0, 8.0, 4.0, 2.0, 1.0, 0.5)


def dirichlet_multinomial_cells(n: NDArray[np.float64], s: NDArray[np.float64] | float,
                                theta: NDArray[np.float64]) -> NDArray[np.float64]:
    """A task's evidence for each class from its count n of one (worker, label) cell:
    lnG(n + s theta) - lnG(s theta) (the overdispersed emission's E-step term, module docstring);
    n log theta where s is infinite (the independent model, Dawid–Skene's term). ``n``: (cells,),
    ``s``: scalar or (cells,), ``theta``: (cells, classes), the cell's confusion entry per class."""
    n = np.asarray(n, dtype=np.float64)[:, None]
    s_col = np.broadcast_to(np.asarray(s, dtype=np.float64), n.shape[:1])[:, None]
    finite = np.isfinite(s_col[:, 0])
    out = n * np.log(theta)
    if finite.any():
        # a single observation: lnG(1 + a) - lnG(a) = ln a exactly (most cells; one log, not two lnG)
        single = finite & (n[:, 0] == 1.0)
        out[single] = np.log(s_col[single] * theta[single])
        many = finite & ~single
        if many.any():
            a = s_col[many] * theta[many]
            out[many] = gammaln(n[many] + a) - gammaln(a)
    return out


def _dirichlet_multinomial_by_column(count: NDArray[np.float64], col: NDArray[np.intp], s_of_col: NDArray[np.float64],
                                     rows: NDArray[np.float64]) -> NDArray[np.float64]:
    """:func:`dirichlet_multinomial_cells` of cells given by their (worker, label) column ``col``
    (``rows[col]`` their confusion entries, ``s_of_col[col]`` their concentrations), equal to it bit
    for bit: lnG(s theta), which depends on the column alone, is evaluated once per column, not once
    per cell (``tests/test_dawid_skene_kinds.py``; docs/performance.md)."""
    s = s_of_col[col]
    theta = rows[col]
    n = count[:, None]
    finite = np.isfinite(s)
    out = np.empty(theta.shape)
    if not finite.all():
        out[~finite] = n[~finite] * np.log(theta[~finite])
    single = finite & (count == 1.0)
    if single.any():
        out[single] = np.log(s[single, None] * theta[single])
    many = finite & ~single
    if many.any():
        a_col = s_of_col[:, None] * rows  # s theta per column: each cell's own product
        lgamma_col = np.zeros(rows.shape)
        fin = np.isfinite(s_of_col)
        lgamma_col[fin] = gammaln(a_col[fin])
        at = col[many]
        out[many] = gammaln(n[many] + a_col[at]) - lgamma_col[at]
    return out


def dirichlet_multinomial_log_likelihood(cells: NDArray[np.float64], totals: NDArray[np.float64],
                                         s: float) -> NDArray[np.float64]:
    """log DM(n | s theta) of groups, from their cells' terms :func:`dirichlet_multinomial_cells`
    summed per group (``cells``) and the groups' totals N = sum_l n_l (``totals``):
    sum_l [lnG(n_l + s theta_l) - lnG(s theta_l)] + lnG(s) - lnG(s + N), without the multinomial
    coefficient (it depends on neither s nor theta). With s infinite it is sum_l n_l log theta_l,
    the multinomial's log-likelihood, its limit."""
    if not np.isfinite(s):
        return np.asarray(cells, dtype=np.float64)
    return np.asarray(cells, dtype=np.float64) + (gammaln(s) - gammaln(s + np.asarray(totals, dtype=np.float64)))


@dataclass
class DawidSkene:
    """EM for the Dawid–Skene latent class model (see the module docstring for the equations).

    Parameters
    ----------
    n_iter : int
        Maximum number of EM iterations.
    tol : float
        Stop when no posterior q_v(z) moves by more than ``tol`` in one iteration.
    smoothing : float
        Symmetric Dirichlet pseudo-count added to every confusion cell and prior in the M-step.
    none_class : bool
        Add the latent class :data:`NONE_CLASS` ("none of these").
    none_prior_votes : float
        Initialisation only: the "none" class starts with this many votes on every element (the
        claims' weights vote for their classes), so an element with one weak claim starts mostly
        "none" and one with many agreeing claims starts mostly that class.
    emission : {"multinomial", "dirichlet_multinomial"}
        Every observation independent given the task's class (Dawid–Skene), or a worker's labels
        of one task correlated, with a concentration per worker learned among ``concentrations``
        (module docstring).
    concentrations : tuple of float
        The values s_w is chosen among; ``inf`` is the independent model.
    """

    n_iter: int = 50
    tol: float = 1e-6
    smoothing: float = 0.5
    none_class: bool = True
    none_prior_votes: float = 1.0
    emission: Literal["multinomial", "dirichlet_multinomial"] = "multinomial"
    concentrations: tuple[float, ...] = CONCENTRATIONS

    # fitted state
    classes_: list[str] | None = None
    labels_: list[str] | None = None
    workers_: list[str] | None = None
    priors_: NDArray[np.float64] | None = None
    errors_: NDArray[np.float64] | None = None  # (workers, classes, labels)
    probas_: NDArray[np.float64] | None = None  # (tasks, classes)
    concentrations_: NDArray[np.float64] | None = None  # (workers,): s_w, inf for the independent model
    n_iter_: int = 0

    def fit(
        self,
        tasks: Sequence[int] | NDArray[np.intp],
        workers: Sequence[str],
        labels: Sequence[str],
        *,
        classes: Sequence[str],
        n_tasks: int | None = None,
        weights: Sequence[float] | NDArray[np.float64] | None = None,
        votes: Sequence[float] | NDArray[np.float64] | None = None,
        vote_classes: Sequence[str | None] | None = None,
        none_votes: Sequence[float] | NDArray[np.float64] | None = None,
        independent_workers: Collection[str] = (),
    ) -> DawidSkene:
        """Fit on a long table of observations (task index, worker, label).

        ``classes``: the latent classes (labels equal to a class name vote for it at
        initialisation); ``n_tasks``: number of tasks (default: max index + 1); ``weights``: each
        observation's weight in both steps (default 1). The initial posterior is a vote: each
        observation gives ``votes`` (default: ``weights``) to the class ``vote_classes`` names
        (default: its label, when that is a class; None: no vote) and ``none_votes`` (default 0)
        to "none of these", which also starts with ``none_prior_votes`` on every task.
        ``independent_workers``: workers that keep the multinomial emission whatever ``emission`` says.
        """
        t = np.asarray(tasks, dtype=np.intp)
        n_obs = t.shape[0]
        w = np.ones(n_obs) if weights is None else np.asarray(weights, dtype=np.float64)
        v0 = w if votes is None else np.asarray(votes, dtype=np.float64)
        n_t = int(n_tasks if n_tasks is not None else (t.max() + 1 if n_obs else 0))
        cls = list(classes) + ([NONE_CLASS] if self.none_class else [])
        k = len(cls)
        worker_names, wi = np.unique(np.asarray(workers, dtype=object).astype(str), return_inverse=True)
        label_names, li = np.unique(np.asarray(labels, dtype=object).astype(str), return_inverse=True)
        self.classes_, self.labels_, self.workers_ = cls, list(label_names), list(worker_names)
        n_w, n_l = len(worker_names), len(label_names)
        # initial posterior: a weighted vote, "none" with its prior votes
        class_of = {name: j for j, name in enumerate(cls)}
        if vote_classes is None:
            lab_class = np.array([class_of.get(name, -1) for name in label_names], dtype=np.intp)
            oc = lab_class[li]
        else:
            oc = np.array([-1 if name is None else class_of.get(name, -1) for name in vote_classes], dtype=np.intp)
        q = np.zeros((n_t, k))
        m = oc >= 0
        np.add.at(q, (t[m], oc[m]), v0[m])
        if self.none_class:
            q[:, k - 1] += self.none_prior_votes
            if none_votes is not None:
                np.add.at(q[:, k - 1], t, np.asarray(none_votes, dtype=np.float64))
        empty = q.sum(axis=1) <= 0
        q[empty] = 1.0
        q /= q.sum(axis=1, keepdims=True)
        independent = np.isin(np.asarray(worker_names, dtype=object), list(independent_workers))
        return self.fit_coded(t, wi, li, n_w, n_l, q, w, independent=independent)

    def fit_coded(self, tasks: NDArray[np.intp], workers: NDArray[np.intp], labels: NDArray[np.intp], n_workers: int,
                  n_labels: int, initial: NDArray[np.float64], weights: NDArray[np.float64] | None = None,
                  independent: NDArray[np.bool_] | None = None) -> DawidSkene:
        """EM from integer-coded observations (task, worker, label indices) and an initial posterior
        ``initial`` (tasks x classes, rows summing to 1): the core :meth:`fit` calls after coding its
        table, for callers that keep their table coded (``sgbelief.fusion.consensus``). The class,
        label and worker names are left as they are. ``independent``: per worker, whether it keeps
        the multinomial emission (default: none does)."""
        t = np.asarray(tasks, dtype=np.intp)
        w = np.ones(t.shape[0]) if weights is None else np.asarray(weights, dtype=np.float64)
        q = np.asarray(initial, dtype=np.float64)
        n_t = q.shape[0]
        # the observations as a sparse (tasks x (worker, label) cells) matrix of weights: both EM
        # steps are then one sparse product each
        cells = sparse.csr_matrix((w, (t, np.asarray(workers, dtype=np.intp) * n_labels + labels)),
                                  shape=(n_t, n_workers * n_labels))
        by_cell = cells.T  # ((worker, label) cells x tasks), for the M-step's product
        groups = _Groups(cells, n_workers, n_labels) if self.emission == "dirichlet_multinomial" else None
        conc = np.full(n_workers, np.inf)
        theta = pi = None
        it = 0
        for it in range(1, self.n_iter + 1):
            theta, pi = self._m_step(q, by_cell, n_workers, n_labels)
            if groups is None:
                q_new = self._e_step(theta, pi, cells)
            else:
                if it >= 2 and it & (it - 1) == 0:  # iterations 2, 4, 8, 16, ... (module docstring)
                    conc = groups.concentrations(theta, q, self.concentrations, independent)
                q_new = groups.e_step(theta, pi, conc)
            delta = float(np.max(np.abs(q_new - q))) if n_t else 0.0
            q = q_new
            if delta <= self.tol:
                break
        if theta is None:  # n_iter == 0: the initial vote
            theta, pi = self._m_step(q, by_cell, n_workers, n_labels)
        self.priors_, self.errors_, self.probas_, self.n_iter_ = pi, theta, q, it
        self.concentrations_ = conc
        return self

    def _m_step(self, q: NDArray[np.float64], by_cell: sparse.csc_matrix, n_w: int,
                n_l: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """pi_z = mean q_v(z) (smoothed); theta_w[z, l] ∝ smoothing + sum of q over w's observations labelled l."""
        k = q.shape[1]
        counts = np.asarray(by_cell @ q)  # ((worker, label) cells, classes)
        counts = counts.reshape(n_w, n_l, k).transpose(0, 2, 1) + self.smoothing  # (workers, classes, labels)
        counts = np.maximum(counts, _EPS)
        theta = counts / counts.sum(axis=2, keepdims=True)
        pi = q.sum(axis=0) + self.smoothing
        pi = np.maximum(pi, _EPS)
        return theta, pi / pi.sum()

    @staticmethod
    def _e_step(theta: NDArray[np.float64], pi: NDArray[np.float64], cells: sparse.csr_matrix) -> NDArray[np.float64]:
        """log q_v(z) = log pi_z + sum_o w_o log theta_{w_o}[z, l_o], normalised per v."""
        n_w, k, n_l = theta.shape
        log_theta = np.log(theta).transpose(0, 2, 1).reshape(n_w * n_l, k)  # ((worker, label) cells, classes)
        log_lik = np.asarray(cells @ log_theta) + np.log(pi)
        log_lik -= log_lik.max(axis=1, keepdims=True)
        q = np.exp(log_lik)
        return q / q.sum(axis=1, keepdims=True)

    def class_index(self, name: str) -> int:
        """Index of a latent class in ``classes_`` (ValueError if unknown)."""
        assert self.classes_ is not None, "fit first"
        return self.classes_.index(name)


class _Groups:
    """The observations as (task, worker, label) cells with their counts, for the overdispersed
    emission: the per-cell terms, their sums per task (E-step) and per worker (the choice of s_w)."""

    def __init__(self, cells: sparse.csr_matrix, n_workers: int, n_labels: int, distinct: bool = True) -> None:
        cells = cells.copy()
        cells.sum_duplicates()
        cells.eliminate_zeros()
        self.n_tasks, self.n_workers, self.n_labels = cells.shape[0], n_workers, n_labels
        self.col = cells.indices.astype(np.intp)
        self.count = cells.data.astype(np.float64)
        # a cell's terms depend on its (worker, label) column and its count alone: with ``distinct``
        # they are computed once per distinct pair, a kind (docs/performance.md)
        self.kinds = _CellKinds.of(self.col, self.count) if distinct else _CellKinds(self.col, self.count, None)
        self.task = np.repeat(np.arange(self.n_tasks, dtype=np.intp), np.diff(cells.indptr))
        self.worker = self.col // n_labels
        # cells -> their task: one sparse product sums a cell term per task, each cell's term read
        # from its kind's row (the same values, added in the cells' order)
        nnz = len(self.count)
        kinds = self.kinds
        by = np.arange(nnz) if kinds.of_cell is None else kinds.of_cell
        self.by_task = sparse.csr_matrix((np.ones(nnz), by, cells.indptr), shape=(self.n_tasks, len(kinds.col)))
        # the (task, worker) groups: each cell's group, the groups' totals N_vw and workers
        group, self.cell_group = np.unique(self.task * n_workers + self.worker, return_inverse=True)
        self.totals = np.bincount(self.cell_group, weights=self.count)
        self.group_worker = (group % n_workers).astype(np.intp)

    @staticmethod
    def _rows(theta: NDArray[np.float64]) -> NDArray[np.float64]:
        """((worker, label) columns, classes): each column's confusion entry per class."""
        n_w, k, n_l = theta.shape
        return theta.transpose(0, 2, 1).reshape(n_w * n_l, k)

    def e_step(self, theta: NDArray[np.float64], pi: NDArray[np.float64],
               conc: NDArray[np.float64]) -> NDArray[np.float64]:
        """log q_v(z) = log pi_z + sum of the task's cell terms (module docstring), normalised per v."""
        kinds = self.kinds  # one term per kind; by_task reads each cell's from its kind's row
        conc_of_col = np.repeat(conc, self.n_labels)  # column w * n_labels + l: worker w's s
        terms = _dirichlet_multinomial_by_column(kinds.count, kinds.col, conc_of_col, self._rows(theta))
        log_lik = np.asarray(self.by_task @ terms) + np.log(pi)
        log_lik -= log_lik.max(axis=1, keepdims=True)
        q = np.exp(log_lik)
        return q / q.sum(axis=1, keepdims=True)

    def concentrations(self, theta: NDArray[np.float64], q: NDArray[np.float64], grid: tuple[float, ...],
                       independent: NDArray[np.bool_] | None = None) -> NDArray[np.float64]:
        """Per worker, the s in ``grid`` of largest Q_w(s) (the first on a tie); inf for the
        ``independent`` workers, whose cells are not evaluated."""
        out = np.full(self.n_workers, np.inf)
        learn = np.ones(self.n_workers, dtype=bool) if independent is None else ~np.asarray(independent, dtype=bool)
        cells = np.flatnonzero(learn[self.worker])
        if not len(grid) or not len(cells):
            return out
        # a single observation's term is ln s + ln theta (dirichlet_multinomial_cells) and its
        # q-weighted ln theta part is the same for every s (inf included, whose term is ln theta):
        # only its ln s is compared. The other cells are evaluated at each s.
        single = self.count[cells] == 1.0
        multi = cells[~single]
        n_groups = len(self.totals)
        singles_per_group = np.bincount(self.cell_group[cells[single]], minlength=n_groups).astype(np.float64)
        qc = q[self.task[multi]]  # (cells, classes): the posterior of each cell's task
        cell_group = self.cell_group[multi]
        kinds = self.kinds.subset(multi)
        rows = self._rows(theta)
        best = None
        for s in grid:
            terms = _dirichlet_multinomial_by_column(kinds.count, kinds.col, np.full(len(rows), s), rows)  # per kind
            per_cell = (qc * (terms if kinds.of_cell is None else terms[kinds.of_cell])).sum(axis=1)
            summed = np.bincount(cell_group, weights=per_cell, minlength=n_groups).astype(np.float64)
            if np.isfinite(s):
                summed += singles_per_group * np.log(s)
            per_group = dirichlet_multinomial_log_likelihood(summed, self.totals, s)
            q_w = np.bincount(self.group_worker, weights=per_group, minlength=self.n_workers)
            if best is None:
                best = q_w
                out[learn] = s
                continue
            better = learn & (q_w > best + 1e-9 * np.abs(best))
            out[better], best[better] = s, q_w[better]
        return out


@dataclass(frozen=True)
class _CellKinds:
    """Cells by kind, a kind being a distinct (column, count) pair: ``col[j]``, ``count[j]`` of kind j
    and each cell's kind ``of_cell`` (None: every cell its own kind, in order). Most cells of a map
    share a pair (a detector's two claims of ``chair`` on an element), and
    :func:`dirichlet_multinomial_cells` is a function of the pair."""

    col: NDArray[np.intp]
    count: NDArray[np.float64]
    of_cell: NDArray[np.intp] | None

    @classmethod
    def of(cls, col: NDArray[np.intp], count: NDArray[np.float64]) -> _CellKinds:
        """The kinds of cells with columns ``col`` and counts ``count``; every cell its own kind when
        there are more kinds than half the cells (reading by kind would cost more than it saves)."""
        pairs = np.stack([col.astype(np.float64), count], axis=1)
        kinds, of_cell = np.unique(pairs, axis=0, return_inverse=True)
        if 2 * len(kinds) > len(col):
            return cls(col, count, None)
        return cls(kinds[:, 0].astype(np.intp), kinds[:, 1].copy(), of_cell.reshape(-1).astype(np.intp))

    def subset(self, cells: NDArray[np.intp]) -> _CellKinds:
        """The kinds of the cells ``cells`` (their indices) alone."""
        if self.of_cell is None:
            return _CellKinds(self.col[cells], self.count[cells], None)
        kinds, of_cell = np.unique(self.of_cell[cells], return_inverse=True)
        return _CellKinds(self.col[kinds], self.count[kinds], of_cell.reshape(-1).astype(np.intp))

"""Static row and column orders of the batched LU: block lower triangular (Dulmage-Mendelsohn)."""

import numpy as np


def pivot_order(mat):
    """Return a row order for elimination without row swaps (partial pivoting on ``mat``)."""
    a = np.array(mat, dtype=float)
    k = a.shape[0]
    rows = list(range(k))
    for j in range(k):
        i = j + int(np.argmax(np.abs(a[j:, j])))
        a[[j, i]] = a[[i, j]]
        rows[j], rows[i] = rows[i], rows[j]
        if a[j, j] != 0.0:
            a[j + 1:] -= np.outer(a[j + 1:, j] / a[j, j], a[j])
    return np.array(rows)


def block_triangular_order(pattern, mat):
    """
    Return ``(row_order, col_order)``: a block lower triangular form with in-block pivots.

    ``pattern`` (bool ``(k, k)``) holds every entry that can be nonzero, ``mat`` is one
    representative matrix (its magnitudes choose the matching and the pivots).  Returns
    ``None`` if the pattern has no perfect matching (structurally singular).
    """
    pattern = np.asarray(pattern, dtype=bool)
    mat = np.asarray(mat, dtype=float)
    a = np.abs(mat)
    k = pattern.shape[0]
    cols_of = [sorted(np.flatnonzero(pattern[i]).tolist(), key=lambda j: -a[i, j])
               for i in range(k)]
    row_of = [-1] * k                      # column -> matched row

    def augment(row, seen):                # Kuhn's augmenting path, largest entries first
        for c in cols_of[row]:
            if c not in seen:
                seen.add(c)
                if row_of[c] < 0 or augment(row_of[c], seen):
                    row_of[c] = row
                    return True
        return False

    for r in range(k):
        if not augment(r, set()):
            return None
    # dependency graph on columns: column c (its matched row) needs the other columns of the row
    needs = [[j for j in np.flatnonzero(pattern[row_of[c]]).tolist() if j != c]
             for c in range(k)]
    blocks = _tarjan(needs)                # dependencies first
    row_order, col_order = [], []
    for block in blocks:
        rows = [row_of[c] for c in block]
        sub = mat[np.ix_(rows, block)]
        order = pivot_order(sub) if len(block) > 1 else [0]
        row_order += [rows[i] for i in order]
        col_order += list(block)
    return np.array(row_order), np.array(col_order)


def _tarjan(needs):
    """Return the strongly connected components of a graph, every dependency first."""
    n = len(needs)
    index, low, on_stack = [-1] * n, [0] * n, [False] * n
    stack, out, counter = [], [], [0]
    for root in range(n):
        if index[root] >= 0:
            continue
        work = [(root, 0)]
        while work:
            v, i = work.pop()
            if i == 0:
                index[v] = low[v] = counter[0]
                counter[0] += 1
                stack.append(v)
                on_stack[v] = True
            recurse = False
            for j in range(i, len(needs[v])):
                w = needs[v][j]
                if index[w] < 0:
                    work.append((v, j + 1))
                    work.append((w, 0))
                    recurse = True
                    break
                if on_stack[w]:
                    low[v] = min(low[v], index[w])
            if recurse:
                continue
            if low[v] == index[v]:
                comp = []
                while True:
                    w = stack.pop()
                    on_stack[w] = False
                    comp.append(w)
                    if w == v:
                        break
                out.append(sorted(comp))
            if work:
                u = work[-1][0]
                low[u] = min(low[u], low[v])
    return out


class LUPlan:
    """The symbolic LU factorization of a bool ``(k, k)`` sparsity pattern in a static order."""

    def __init__(self, pattern, row_order=None, col_order=None):
        pattern = np.asarray(pattern, dtype=bool)
        k = pattern.shape[0]
        if pattern.shape != (k, k):
            raise ValueError(f'pattern: got shape {pattern.shape}, expected (k, k)')
        self.k = k
        self.row_order = np.arange(k) if row_order is None else np.asarray(row_order)
        self.col_order = np.arange(k) if col_order is None else np.asarray(col_order)
        self.natural_cols = bool(np.array_equal(self.col_order, np.arange(k)))
        a = pattern[np.ix_(self.row_order, self.col_order)] | np.eye(k, dtype=bool)
        for j in range(k):  # symbolic elimination: row i gains row j's pattern
            rows = np.flatnonzero(a[j + 1:, j]) + j + 1
            a[np.ix_(rows, np.arange(j, k))] |= a[j, j:]
        rr, cc = np.nonzero(a)
        self.nnz = rr.size
        slot = np.full((k, k), -1)
        slot[rr, cc] = np.arange(self.nnz)
        self.src_row = self.row_order[rr]   # where each stored entry comes from in mat
        self.src_col = self.col_order[cc]
        self.diag = slot[np.arange(k), np.arange(k)]
        self.l_rows, self.l_idx, self.u_cols, self.u_idx, self.update = [], [], [], [], []
        for j in range(k):
            rows = np.flatnonzero(a[j + 1:, j]) + j + 1
            cols = np.flatnonzero(a[j, j + 1:]) + j + 1
            self.l_rows.append(rows)
            self.l_idx.append(slot[j + 1:, j][rows - j - 1])
            self.u_cols.append(cols)
            self.u_idx.append(slot[j, cols])
            self.update.append(slot[np.ix_(rows, cols)].ravel())
        # triangular solves as plain row updates (slices, no gathers): per pivot j the
        # (row, slot) pairs of L's column j and of U's row j
        self.l_pairs = [list(zip(r.tolist(), i.tolist())) for r, i in
                        zip(self.l_rows, self.l_idx)]
        self.u_pairs = [list(zip(c.tolist(), i.tolist())) for c, i in
                        zip(self.u_cols, self.u_idx)]
        self.diag_list = self.diag.tolist()
        self.pivot_col = self.col_order.tolist()   # original column of each pivot
        # inverse: Z = U^-1 L^-1 (pivot order), whose row j is nonzero only in columns
        # lo[j]..hi[j]: L^-1 row i spans env[i]..i, and U^-1 mixes in the rows below
        env = list(range(k))
        for j in range(k):
            for i in self.l_rows[j].tolist():
                env[i] = min(env[i], env[j])
        lo, hi = env[:], list(range(k))
        for j in range(k - 1, -1, -1):
            for c in self.u_cols[j].tolist():
                lo[j], hi[j] = min(lo[j], lo[c]), max(hi[j], hi[c])
        self.env, self.z_lo, self.z_hi = env, lo, hi
        self.perm_sign = -1.0 if (inversions(self.row_order)
                                  + inversions(self.col_order)) % 2 else 1.0
        self._slot = slot
        self._pivot_row = np.argsort(self.row_order)     # original row -> pivot position
        self._pivot_pos = np.argsort(self.col_order)     # original column -> pivot position
        self.entries = None

    def set_entries(self, rows, cols):
        """Fix the order ``rows``, ``cols`` in which :class:`Factored` gets a matrix's nonzeros."""
        rows, cols = np.asarray(rows, dtype=int), np.asarray(cols, dtype=int)
        pr, pc = self._pivot_row[rows], self._pivot_pos[cols]
        slots = self._slot[pr, pc]
        if np.any(slots < 0):
            raise ValueError("rows, cols: an entry lies outside the plan's pattern")
        self.entries = (rows, cols)
        self.entry_slot = slots
        by_col = np.argsort(pc, kind='stable')     # entries grouped by pivot column
        counts = np.bincount(pc, minlength=self.k)
        if np.any(counts == 0):
            raise ValueError('rows, cols: a column has no entry (structurally singular)')
        self.entry_col_start = np.concatenate([[0], np.cumsum(counts)[:-1]])
        # the entries of each pivot column, padded with a zero entry (index len(rows)): (k, w)
        width = int(counts.max())
        pad = np.full((self.k, width), rows.size)
        for j in range(self.k):
            own = by_col[self.entry_col_start[j]:self.entry_col_start[j] + counts[j]]
            pad[j, :own.size] = own
        self.entry_col_pad = pad


def static_plan(pattern, sample):
    """Return the :class:`LUPlan` in block triangular order (else pivoting on ``sample``)."""
    order = block_triangular_order(pattern, sample)
    return LUPlan(pattern, *(order or (pivot_order(sample), None)))


def inversions(order):
    """Return the number of inversions of a permutation (its sign's parity)."""
    order = [int(i) for i in order]
    return sum(1 for i in range(len(order)) for j in range(i + 1, len(order))
               if order[i] > order[j])

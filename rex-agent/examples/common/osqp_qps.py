"""OSQP (compiled C, through its Python package) on the QPs bench_qp wrote.

Reads the JSON file given as argv[1] (header: n, m, p_diag, a_rows, a_cols,
eps, repeats; then per QP: q, a_values, l, u), sets OSQP up once with the
first QP's data, and solves every QP in order: its data updated in place,
warm-started from the previous QP's solution, `repeats` times (the warm start
set again before each). Writes to argv[2], one line per QP: OSQP's own
update + solve time of each repeat in microseconds (its C timers), the
wall time of the same calls in Python, the iterations, the status and the
solution.
"""
import json
import sys
import time

import numpy as np
import osqp
import scipy.sparse as sp

with open(sys.argv[1]) as f:
    head = json.loads(f.readline())
    qps = [json.loads(line) for line in f]

n, m = head["n"], head["m"]
rows, cols = np.array(head["a_rows"]), np.array(head["a_cols"])
nnz = len(rows)
# The CSC order of the triplets: build once with their indices as values.
order = sp.csc_matrix((np.arange(1, nnz + 1, dtype=float), (rows, cols)), shape=(m, n))
perm = order.data.astype(int) - 1
P = sp.diags(head["p_diag"], format="csc")
P = sp.triu(P, format="csc")


def a_matrix(values):
    a = order.copy()
    a.data = np.asarray(values, dtype=float)[perm]
    return a


first = qps[0]
solver = osqp.OSQP()
solver.setup(
    P,
    np.array(first["q"]),
    a_matrix(first["a_values"]),
    np.array(first["l"]),
    np.array(first["u"]),
    eps_abs=head["eps"],
    eps_rel=head["eps"],
    max_iter=100000,
    polish=False,
    warm_starting=True,
    verbose=False,
)

out = []
x_prev, y_prev = None, None
for qp in qps:
    q, l, u = np.array(qp["q"]), np.array(qp["l"]), np.array(qp["u"])
    ax = np.asarray(qp["a_values"], dtype=float)[perm]
    own, wall = [], []
    res = None
    for _ in range(head["repeats"]):
        if x_prev is not None:
            solver.warm_start(x=x_prev, y=y_prev)
        t = time.perf_counter()
        solver.update(q=q, l=l, u=u, Ax=ax)
        res = solver.solve()
        wall.append((time.perf_counter() - t) * 1e6)
        own.append((res.info.update_time + res.info.solve_time) * 1e6)
    status = res.info.status
    out.append(
        {
            "own_us": own,
            "wall_us": wall,
            "iter": int(res.info.iter),
            "status": str(status),
            "x": [float(v) for v in res.x],
        }
    )
    x_prev, y_prev = res.x.copy(), res.y.copy()

with open(sys.argv[2], "w") as f:
    for o in out:
        f.write(json.dumps(o) + "\n")

"""Error against the number of differentiations k, on the gallery's constant problems.

Measures what `lsc.complete` accepts for k (at most the index + `K_ABOVE_INDEX`): for each problem
and method, the completion with k = index + extra is integrated exactly (method='expm',
max_step=0.01) from the exact start over (0, 2), and the largest relative error against the exact
solution at 11 times is printed. The limit is lifted here so the scan can go past it.

Run: ``python examples/scan_k.py`` (a few minutes).
"""
import warnings

import numpy as np

import lsc
import lsc._index
from lsc import gallery

lsc._index.K_ABOVE_INDEX = 100  # measure beyond the accepted range
warnings.simplefilter("ignore")  # close rank calls at large k are part of what is measured

PROBLEMS = {
    "prescribed_path": lambda: gallery.prescribed_path(t_span=(0, 2)),
    "mechanical": lambda: gallery.mechanical(t_span=(0, 2)),
    "nilpotent_chain(1)": lambda: gallery.nilpotent_chain(1, seed=1, t_span=(0, 2)),
    "nilpotent_chain(3)": lambda: gallery.nilpotent_chain(3, seed=3, t_span=(0, 2)),
    "nilpotent_chain(5)": lambda: gallery.nilpotent_chain(5, seed=5, t_span=(0, 2)),
    "random_pencil": lambda: gallery.random_pencil(t_span=(0, 2)),
}
EXTRA = [0, 5, 10, 12, 15, 20, 25, 30]


def main():
    print("problem index method " + " ".join(f"+{e}" for e in EXTRA))
    for name, make in PROBLEMS.items():
        p = make()
        index = lsc.differentiation_index(p.dae)
        for method, lam in [("alternative", 2.0), ("standard", None), ("stabilized", 2.0)]:
            errors = []
            for extra in EXTRA:
                try:
                    c = lsc.complete(p.dae, method, lam=lam, k=index + extra)
                    res = lsc.solve_completion(c, p.t_span, p.x0, method="expm", max_step=0.01,
                                               t_eval=np.linspace(*p.t_span, 11))
                    X = p.exact(res.t)
                    errors.append(f"{np.max(np.abs(res.x - X) / (1 + np.abs(X))):.1e}")
                except (ValueError, np.linalg.LinAlgError) as exc:
                    errors.append(type(exc).__name__)
            print(name, index, method, " ".join(errors), flush=True)


if __name__ == "__main__":
    main()

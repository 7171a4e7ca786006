"""Fits the scene verdict's log-odds (verdict::SCENE_ODDS) from a cue dump.

Inputs: the records (`mtpcr eval ... --records R.jsonl`) and the stderr (`E.err`) of a build
with `cue-dump.patch` applied, run with MTPCR_CUES=1 (one `CUE {...}` line per pair, in the
records' order). Prints, for the six committed cues alone and with each candidate cue added,
the share of registered pairs doubted when at most 5 % of the failed pairs are confident,
fitted on four scenes and judged on the fifth (LOSO) and on all records (in-sample), then
the chosen nine-cue fit in the units of `SceneOdds`.

    python3 fit_scene_odds.py cm.jsonl cm.err cl.jsonl cl.err
"""
import json
import sys

import numpy as np

L = np.log1p


def load(rec, err):
    records = [json.loads(line) for line in open(rec)]
    cues = [
        json.loads(line[4:].replace(":NaN", ":-1").replace(":inf", ":-1"))
        for line in open(err)
        if line.startswith("CUE ")
    ]
    assert len(records) == len(cues), (len(records), len(cues))
    for r, c in zip(records, cues):
        r.update({"c_" + k: v for k, v in c.items()})
    return records


def six(r):
    return [
        L(r["support"]),
        L(r["rival_support"]),
        min(r["free_space"] or 0, 0.3),
        np.log(max(r["constraint"] or 0, 0) + 0.001),
        r["overlap"],
        r["residual"] if np.isfinite(r["residual"]) else 5,
    ]


EXTRA = {
    "free_share": lambda r: min(r["c_free_share"], 0.3) if r["c_free_share"] >= 0 else 0,
    "landed": lambda r: L(r["c_inside"]),
    "tight": lambda r: L(r["c_tight"]),
    "matches": lambda r: L(r["c_n"]),
    "near_half": lambda r: L(r["c_near_half"]),
    "rivals": lambda r: L(r["c_rivals"]),
    "rival_deg": lambda r: (r["c_rival_deg"] if r["c_rival_deg"] >= 0 else 180) / 180,
    "rival_free": lambda r: min(r["c_rival_free"], 0.3) if r["c_rival_free"] >= 0 else 0.3,
    "rival_overlap_gap": lambda r: r["overlap"] - max(r["c_rival_overlap"], 0),
    "overlap_half_eps": lambda r: r["c_overlap_half"],
    "overlap_two_eps": lambda r: r["c_overlap_double"],
    "icp_degrees": lambda r: min(r["c_icp_deg"], 30) / 30,
    "icp_shift": lambda r: min(r["c_icp_shift"] / r["c_shift"], 0.1) * 10,
    "second_look": lambda r: float(r["c_second"]),
}


def fit(X, y, l2=1e-3):
    X1 = np.c_[np.ones(len(X)), X]
    w = np.zeros(X1.shape[1])
    for _ in range(50):
        p = 1 / (1 + np.exp(-X1 @ w))
        H = X1.T @ (X1 * (p * (1 - p))[:, None]) + l2 * np.eye(len(w))
        w += np.linalg.solve(H, X1.T @ (y - p) - l2 * w)
    return w


def scores(X, y, train):
    mu, sd = X[train].mean(0), X[train].std(0) + 1e-9
    w = fit((X[train] - mu) / sd, y[train])
    return np.c_[np.ones(len(X)), (X - mu) / sd] @ w, (w[0] - (mu * w[1:] / sd).sum(), w[1:] / sd)


def doubted_at(s, y, cap=0.05):
    fail = np.sort(s[y == 0])
    t = next(t for t in np.r_[fail, np.inf] if (s[y == 0] >= t).mean() <= cap)
    return (s[y == 1] < t).mean(), t


def main(args):
    recs = sum((load(a, b) for a, b in zip(args[::2], args[1::2])), [])
    y = np.array([r["registered"] for r in recs], float)
    scene = np.array([r["pair"].split("/")[0] for r in recs])
    base = np.array([six(r) for r in recs])

    def evaluate(X):
        loso = np.zeros(len(y))
        for sc in np.unique(scene):
            loso[scene == sc] = scores(X, y, scene != sc)[0][scene == sc]
        return doubted_at(loso, y)[0], doubted_at(scores(X, y, np.ones(len(y), bool))[0], y)[0]

    print(f"{len(recs)} records, {int(y.sum())} registered")
    print("six cues: LOSO %.3f, in-sample %.3f" % evaluate(base))
    for name, f in EXTRA.items():
        X = np.c_[base, [f(r) for r in recs]]
        print("+ %-18s LOSO %.3f, in-sample %.3f" % ((name,) + evaluate(X)))
    chosen = ["free_share", "landed", "tight"]
    X = np.c_[base, [[EXTRA[k](r) for k in chosen] for r in recs]]
    print("+ " + ", ".join(chosen) + ": LOSO %.3f, in-sample %.3f" % evaluate(X))
    _, (b, w) = scores(X, y, np.ones(len(y), bool))
    print("weights: base %.3f, " % b + ", ".join("%.3f" % v for v in w))


if __name__ == "__main__":
    main(sys.argv[1:])

"""Solve MDPs with pymdptoolbox (the solver the paper's authors used), as an
independent check of frugal's own value and policy iteration.

Reads JSON from stdin: a list of {"states", "actions", "p", "r", "gamma"} with p flat in
(A, S, S) order and r flat in (S, A) order (frugal's `Mdp` layout). Writes a JSON list of
{"pi_policy", "pi_values", "vi_policy"} to stdout.
"""
import json
import sys

import mdptoolbox.mdp
import numpy as np

out = []
for case in json.load(sys.stdin):
    s, a = case["states"], case["actions"]
    p = np.array(case["p"], dtype=float).reshape(a, s, s)
    r = np.array(case["r"], dtype=float).reshape(s, a)
    pi = mdptoolbox.mdp.PolicyIteration(p, r, case["gamma"], eval_type=0)
    pi.run()
    vi = mdptoolbox.mdp.ValueIteration(p, r, case["gamma"], epsilon=1e-12, max_iter=100000)
    vi.run()
    out.append({
        "pi_policy": [int(x) for x in pi.policy],
        "pi_values": [float(x) for x in pi.V],
        "vi_policy": [int(x) for x in vi.policy],
    })
json.dump(out, sys.stdout)

"""Verdicts of PyPI rtamt (discrete-time STL) on the signals tests/monitor_rtamt.rs
hands it: on standard input a JSON list of cases, each {"spec": STL text,
"vars": {name: [one value per step]}} sampled at steps 0, 1, 2, ...; on standard
output a JSON list of verdicts, true when the formula holds at step 0 (its
robustness there is not negative)."""

import json
import sys

import rtamt


def verdict(case):
    spec = rtamt.StlDiscreteTimeSpecification()
    for name in case["vars"]:
        spec.declare_var(name, "float")
    spec.spec = case["spec"]
    spec.parse()
    signals = {name: [float(x) for x in xs] for name, xs in case["vars"].items()}
    steps = len(next(iter(signals.values())))
    signals["time"] = list(range(steps))
    robustness = spec.evaluate(signals)
    return robustness[0][1] >= 0


def main():
    cases = json.load(sys.stdin)
    json.dump([verdict(c) for c in cases], sys.stdout)


if __name__ == "__main__":
    main()

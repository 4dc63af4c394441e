"""What the fast lane's early-Submit wait costs a long loop of launches: 500 three-array launches
then one synchronize, per launch (best of 7), with the lane's first wait at its default
(PUMP_AFTER_LANE_S, 40 us, doubling with each early Submit) and at 2 ms (the gRPC rule), twice
each in turn. Usage: WEFT_DAEMON=... python3 bench/prof_pump.py [--device cpu] [-n 500]"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "clients" / "python"))

import weft as wp  # noqa: E402 - kernel annotations name it at module scope
from weft import _runtime  # noqa: E402


@wp.kernel
def three_args(a: wp.array(dtype=float), b: wp.array(dtype=float), c: wp.array(dtype=float)):
    pass


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--device", default="cpu")
    ap.add_argument("-n", type=int, default=500)
    args = ap.parse_args()
    arrays = [wp.zeros(16, dtype=float, device=args.device) for _ in range(3)]

    def loop():
        for _ in range(args.n):
            wp.launch(three_args, dim=1, inputs=arrays, device=args.device)

    loop()
    wp.synchronize()
    default = _runtime.PUMP_AFTER_LANE_S
    for after in (default, 0.002, default, 0.002):
        _runtime.PUMP_AFTER_LANE_S = after      # read at each sync point
        best = None
        for _ in range(7):
            wp.synchronize()
            t = time.perf_counter()
            loop()
            wp.synchronize()
            dt = (time.perf_counter() - t) / args.n
            best = dt if best is None else min(best, dt)
        print(f"lane early-Submit wait {after * 1e6:6.0f} us: {best * 1e6:6.2f} us per launch "
              f"({args.n} launches + sync, best of 7)")
    _runtime.PUMP_AFTER_LANE_S = default


if __name__ == "__main__":
    main()

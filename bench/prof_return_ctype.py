"""The cost of one wp.from_torch(t, return_ctype=True) of a tensor converted before (the loop
of bench_interop's return_ctype mode, without the launch): the remembered-descriptor look-up in
C (weft._torch_descriptor) and in Python, alternating --rounds times in one process on a CPU
tensor (the look-up is the same for a CUDA one). Prints microseconds per call (timeit).
Usage: python3 bench/prof_return_ctype.py [--calls 200000] [--rounds 3]   (WEFT_DAEMON: the weftd)"""
from __future__ import annotations

import argparse
import sys
import timeit
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent / "clients" / "python"))

import bench_common as bc  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--calls", type=int, default=200_000)
    ap.add_argument("--rounds", type=int, default=3)
    args = ap.parse_args()
    import torch

    with bc.WeftSession() as (wp, _rt):
        from weft.interop import torch as weft_torch

        t = torch.randn(1024)
        first = wp.from_torch(t, return_ctype=True)
        native = weft_torch._native_descriptor()
        ways = [("C", native)] if native is not None else []
        ways.append(("Python", None))
        for r in range(args.rounds):
            for name, lookup in ways:
                weft_torch._NATIVE_DESCRIPTOR = lookup
                desc = wp.from_torch(t, return_ctype=True)
                assert bytes(desc) == bytes(first)
                us = timeit.timeit(lambda: wp.from_torch(t, return_ctype=True),
                                   number=args.calls) / args.calls * 1e6
                print(f"round {r}  look-up in {name:6s}  {us:.2f} us per from_torch(return_ctype=True)",
                      flush=True)
        weft_torch._NATIVE_DESCRIPTOR = native


if __name__ == "__main__":
    main()

"""Command line: ``socbjax demo`` (also ``python -m socbjax demo``)."""

from __future__ import annotations

import argparse
import sys

__all__ = ["main"]


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="socbjax",
        description="SOCB simulator of slender elastic filaments (units: µm, pN, s; EI in pN·µm²).",
    )
    sub = parser.add_subparsers(dest="command", required=True)
    demo = sub.add_parser(
        "demo",
        help="run the cantilever and buckling validations, print the table, write a figure",
        description="Cantilever (paper Fig. 4A) and buckling (Fig. 5c) validations against the exact "
        "elastica and Euler loads; writes demo.json and demo.png.",
    )
    demo.add_argument("--out", default="socbjax-demo", help="output folder (default: ./socbjax-demo)")
    demo.add_argument("--quick", action="store_true", help="fewer node counts (faster smoke run)")
    return parser


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    if args.command == "demo":
        from ._demo import run_demo

        run_demo(args.out, quick=args.quick)
        return 0
    return 2  # pragma: no cover - argparse enforces the choices


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())

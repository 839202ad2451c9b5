"""`python -m rotjax`: a short demo of the conversions on Nikravesh's worked examples.

`python -m rotjax bench [--quick] [--out DIR]` runs the speed/accuracy benchmark;
`python -m rotjax bench report` regenerates its tables and plot from `docs/bench.json`.
"""

from __future__ import annotations

import sys


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv and argv[0] == "bench":
        from ._bench import main as bench_main

        return bench_main(argv[1:])
    from ._demo import main as demo_main

    return demo_main(argv)


if __name__ == "__main__":
    raise SystemExit(main())

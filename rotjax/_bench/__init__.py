"""The speed/accuracy benchmark behind ``python -m rotjax bench`` (a development tool: it needs
the ``bench`` extra, and nothing in rotjax imports it).

Modules:

* ``cases``: ``CASES``, the registry of operations and their contenders;
* ``timing``: interleaved rounds, medians of per-round ratios, the copy kernel;
* ``accuracy``: the adversarial sets, their mpmath references, one error function per output;
* ``runner``: the measurement loop; ``report``: tables, plot, README block; ``cli``: arguments.

Adding a case: append a ``Case`` to ``CASES`` in ``cases.py``:

    Case(
        "nined_to_matrix",                  # the row's name
        "matrix",                           # key of INPUTS (add one for a new kind of input)
        lambda peers: ordered(              # rotjax first, its default method first of all
            [rotjax_fn("nined_to_matrix")],
            # peers: scipy_like(peers, "from_matrix", "as_matrix"), jaxlie_builder(...), ...
        ),
        accuracy.some_errors,               # Evaluator -> {set name: absolute errors}
        quick=False,                        # part of --quick
    )

A contender is ``Contender(impl, method, fn, traceable)``; ``fn`` maps the input batch to the
output in rotjax's convention. Two contenders of one operation (say a ``Rotation`` method and
the function it calls) are two entries with distinct ``method`` strings. The error function
receives an ``accuracy.Evaluator`` (``ev.run(x)``, ``ev.run_sets({name: x})``, the sets and
references in ``ev.acc``) and returns absolute errors; the runner converts them to eps. The
copy kernel's widths come from the shapes, and the tables and plot pick up new rows by
themselves; ``report.HEADLINE_OPS`` lists the rows of the README's headline table.
"""

from .cli import main as main

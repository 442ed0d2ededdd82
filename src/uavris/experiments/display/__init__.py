"""How results are shown: tables, figures, progress bars and TensorBoard logs.

Modules: :mod:`.tables` (Markdown tables, numbers, percentages and confidence intervals as
text, "n/a" for a missing value), :mod:`.plots` (figures fit for a paper: PNG and PDF, the
shared colours and reference lines) and :mod:`.progress` (progress bars, TensorBoard
writers). Lives here: nothing at package level. Not here: the numbers themselves
(:mod:`uavris.stats`, the pipelines).
"""

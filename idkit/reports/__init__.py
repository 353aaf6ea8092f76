"""Reports: formatting only. They read study results and never run a study.

``files`` (atomic writes), ``result_file`` (the one ``result.json`` writer), ``tables`` (the one
Markdown table writer), ``plots``, and one module per task (``single``, ``paper``, ``robustness``,
``kuka``) with ``text(result) -> str`` and ``write(result, out_dir, plots) -> files``.
"""

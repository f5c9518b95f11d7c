"""A command line run in this process: its entry function with the arguments, the exit code
(argparse's usage errors included) and what it printed. The installed entry points keep a
real subprocess test each (test_sortie, test_campaigns, test_docs)."""

from __future__ import annotations

from collections.abc import Callable, Sequence


def run_cli(
    main: Callable[[Sequence[str]], int], argv: Sequence[str], capsys
) -> tuple[int, str, str]:
    """``main(argv)`` -> (exit code, stdout, stderr), read through pytest's ``capsys``."""
    capsys.readouterr()  # what the test printed before is not the command's
    try:
        code = main(list(argv))
    except SystemExit as exc:  # argparse's usage errors and --help
        code = exc.code if isinstance(exc.code, int) else 1
    out, err = capsys.readouterr()
    return code, out, err

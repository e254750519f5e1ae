"""The one error type of bad input: whatever the user gave (a file, a field, an option) that
the program cannot use.

Every check of the user's input raises `InputError` (or a subclass that names its domain:
`RigError`, `ScenarioError`, ...), with a message that names the file or option, what is wrong
and the fix. The `sds` command reports it in one line and exits with code 2; any other
exception is the program's own fault and keeps its traceback (exit code 1). It is a
`ValueError`, so that code that catches a `ValueError` for a bad value still catches it.
"""

from __future__ import annotations


class InputError(ValueError):
    """Bad input from the user: the message names what (file, field, option) and the fix."""

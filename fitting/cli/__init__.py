"""Command-line entry points of the `fitting` package (dispatched by `hertzchain`)."""

# Exit statuses of the fitting commands (`hertzchain` itself answers 2 to an input error).
EXIT_INPUT_ERROR = 2
EXIT_NOT_CONVERGED = 3


def exit_codes_epilog(not_converged: str) -> str:
    """The `--help` epilog listing a command's exit statuses; `not_converged`: what status 3
    means for it."""
    return (f"exit status: 0 done; {EXIT_INPUT_ERROR} bad input (the message names the field and the fix); "
            f"{EXIT_NOT_CONVERGED} {not_converged} (the results are written, and say which fits did not converge)")

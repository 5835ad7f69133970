"""Usage errors of `vln-pilot` that name the valid choices: an unknown command lists the commands, an unknown
option points to the command's help when no option is close to it (one line, exit code 2)."""

from __future__ import annotations

from typer._click import Command, Context
from typer._click.exceptions import ClickException, NoSuchOption, UsageError
from typer.core import TyperGroup


class ListingGroup(TyperGroup):
    """A command group whose "No such command" line ends with the valid commands."""

    def resolve_command(self, ctx: Context, args: list[str]) -> tuple[str | None, Command | None, list[str]]:
        try:
            return super().resolve_command(ctx, args)
        except UsageError as exc:
            if args and not args[0].startswith("-") and self.get_command(ctx, args[0]) is None:
                exc.message = f"{exc.message} Valid commands: {', '.join(self.list_commands(ctx))}."
            raise


def usage_message(exc: ClickException) -> str:
    """The framework's message, with where to find the valid options when it suggests none."""
    message = exc.format_message()
    if isinstance(exc, NoSuchOption) and not exc.possibilities:
        message = f"{message}; the valid options: see {_command_line(exc.ctx)} --help"
    return message


def _command_line(ctx: Context | None) -> str:
    """`vln-pilot` and the subcommands of `ctx` (the program's own name varies: `python -m vlnpilot`...)."""
    names = []
    while ctx is not None and ctx.parent is not None:
        names.append(ctx.info_name or "")
        ctx = ctx.parent
    return " ".join(["vln-pilot", *reversed(names)])

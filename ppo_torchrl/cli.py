"""`key=value` arguments for the small entry points (evaluate, export), checked like Hydra's."""

from __future__ import annotations

from typing import Any, Dict, Optional, Tuple

from ppo_torchrl.errors import ConfigError

TRUE, FALSE = {"true", "1", "yes"}, {"false", "0", "no"}


def parse_args(argv: list[str], spec: Dict[str, Any], usage: str, help: Optional[Dict[str, str]] = None,
               about: str = "") -> Dict[str, Any]:
    """spec: name -> default (its type is the default's; None means a required string).

    help: name -> one line of meaning; with --help or -h anywhere, print the usage page and exit 0.
    """
    if "--help" in argv or "-h" in argv:
        print_help(usage, {k: ((help or {}).get(k, ""), default) for k, default in spec.items()}, about)
    values = dict(spec)
    for arg in argv:
        key, sep, raw = arg.partition("=")
        if not sep or key not in spec:
            raise ConfigError(f"unexpected argument '{arg}'; usage: {usage}")
        default = spec[key]
        try:
            if isinstance(default, bool):
                if raw.lower() not in TRUE | FALSE:
                    raise ValueError
                values[key] = raw.lower() in TRUE
            elif isinstance(default, int):
                values[key] = int(raw)
            else:
                values[key] = raw
        except ValueError:
            raise ConfigError(f"{key}={raw}: expected a {type(default).__name__}; usage: {usage}") from None
    missing = [k for k, v in values.items() if v is None]
    if missing:
        raise ConfigError(f"missing {', '.join(k + '=...' for k in missing)}; usage: {usage}")
    return values


def print_help(usage: str, arguments: Dict[str, Tuple[str, Any]], about: str = "") -> None:
    """The usage page of an entry point: what it does, then each argument's meaning and default."""
    lines = [f"usage: {usage}", ""] + ([about, ""] if about else []) + ["arguments:"]
    width = max(len(name) for name in arguments) + 2
    for name, (meaning, default) in arguments.items():
        shown = str(default).lower() if isinstance(default, bool) else default
        shown = "required" if default is None else "default: none" if default == "" else f"default: {shown}"
        lines.append(f"  {name:<{width}}{meaning} ({shown})")
    print("\n".join(lines))
    raise SystemExit(0)


def run(main) -> None:
    """Run an entry point's main(argv) through the one error path (errors.py), signals included."""
    import sys

    from ppo_torchrl import signals
    from ppo_torchrl.errors import guarded

    signals.install()
    guarded(main, sys.argv[1:])

"""marl: self-play league training and Elo evaluation of multi-agent RL policies.

The league stores games without importing them (:mod:`selfplay_cli.league.games`): here, where the package starts,
it is given the game registry to look their declarations up in (imported only when a declaration is asked for)."""

__version__ = "0.1.0"


def _declaration(name: str) -> object | None:
    from .envs import get_env
    from .envs.contract import UnknownEnvError

    try:
        return get_env(name)
    except UnknownEnvError:
        return None


def _canonical_option(value: object) -> object:
    from .envs.contract import canonical_option

    return canonical_option(value)


from .league.games import use_catalog  # noqa: E402  (after the two functions it is given)

use_catalog(_declaration, _canonical_option)

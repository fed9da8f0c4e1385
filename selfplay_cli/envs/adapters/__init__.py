"""Adapters that make users' games `marl` games: :mod:`.pettingzoo` turns any PettingZoo ``AECEnv`` or
``ParallelEnv`` factory into an :class:`~selfplay_cli.envs.contract.EnvSpec` (what the game declares read by
:mod:`.pettingzoo_probe`) and a batched core of N copies (:mod:`.pettingzoo_core`); :mod:`.openspiel` does the same
for OpenSpiel's games (``openspiel:GAME(params)``), a core of N OpenSpiel states."""

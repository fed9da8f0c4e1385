"""schema 2 (runs, players, tags, matches with work keys, the game ledger)

The baseline: the league as the last release before Alembic wrote it (its ``meta.schema_version`` 2). Frozen here,
table by table, as it was then: later changes to the models are later revisions, never edits of this one.
"""

import sqlalchemy as sa
from alembic import op

revision = "0002"
down_revision = None
branch_labels = None
depends_on = None


def upgrade() -> None:
    """Create the tables and indexes of schema 2."""
    op.create_table(
        "meta",
        sa.Column("key", sa.String(64), primary_key=True),
        sa.Column("value", sa.Text(), nullable=False),
    )
    op.create_table(
        "runs",
        sa.Column("id", sa.Integer(), primary_key=True),
        sa.Column("name", sa.String(200), nullable=False, unique=True),
        sa.Column("env", sa.String(100), nullable=False),
        sa.Column("algo", sa.String(100), nullable=True),
        sa.Column("config", sa.JSON(), nullable=False),
        sa.Column("status", sa.String(32), nullable=False),
        sa.Column("created_at", sa.DateTime(), nullable=False),
        sa.Column("updated_at", sa.DateTime(), nullable=False),
    )
    op.create_index("ix_runs_env", "runs", ["env"])
    op.create_table(
        "players",
        sa.Column("id", sa.Integer(), primary_key=True),
        sa.Column("env", sa.String(100), nullable=False),
        sa.Column("kind", sa.String(16), nullable=False),
        sa.Column("name", sa.String(200), nullable=False),
        sa.Column("run_id", sa.Integer(), sa.ForeignKey("runs.id"), nullable=True),
        sa.Column("step", sa.BigInteger(), nullable=False),
        sa.Column("episode", sa.BigInteger(), nullable=False),
        sa.Column("algo", sa.String(100), nullable=True),
        sa.Column("path", sa.Text(), nullable=True),
        sa.Column("sha256", sa.String(64), nullable=True),
        sa.Column("parent_id", sa.Integer(), sa.ForeignKey("players.id"), nullable=True),
        sa.Column("elo", sa.Float(), nullable=False),
        sa.Column("games", sa.Integer(), nullable=False),
        sa.Column("removed", sa.Boolean(), nullable=False),
        sa.Column("removed_at", sa.DateTime(), nullable=True),
        sa.Column("created_at", sa.DateTime(), nullable=False),
        sa.Column("meta", sa.JSON(), nullable=False),
        sa.UniqueConstraint("env", "run_id", "name", name="uq_players_env_run_name"),
    )
    op.create_index("ix_players_run_id", "players", ["run_id"])
    op.create_index("ix_players_env_kind", "players", ["env", "kind"])
    op.create_index("ix_players_env_name", "players", ["env", "name"])
    if op.get_bind().dialect.name in ("sqlite", "postgresql"):  # partial indexes: bot names unique per env
        op.create_index("uq_players_env_name_no_run", "players", ["env", "name"], unique=True,
                        sqlite_where=sa.text("run_id IS NULL"), postgresql_where=sa.text("run_id IS NULL"))
    op.create_table(
        "tags",
        sa.Column("id", sa.Integer(), primary_key=True),
        sa.Column("env", sa.String(100), nullable=False),
        sa.Column("tag", sa.String(200), nullable=False),
        sa.Column("player_id", sa.Integer(), sa.ForeignKey("players.id", ondelete="CASCADE"), nullable=False),
        sa.Column("created_at", sa.DateTime(), nullable=False),
        sa.UniqueConstraint("env", "tag", name="uq_tags_env_tag"),
    )
    op.create_index("ix_tags_player_id", "tags", ["player_id"])
    op.create_table(
        "matches",
        sa.Column("id", sa.Integer(), primary_key=True),
        sa.Column("env", sa.String(100), nullable=False),
        sa.Column("kind", sa.String(32), nullable=False),
        sa.Column("params", sa.JSON(), nullable=False),
        sa.Column("created_at", sa.DateTime(), nullable=False),
        sa.Column("work_key", sa.String(200), nullable=True),
    )
    op.create_index("ix_matches_env", "matches", ["env"])
    op.create_index("uq_matches_work_key", "matches", ["work_key"], unique=True)
    op.create_table(
        "games",
        sa.Column("id", sa.Integer(), primary_key=True),
        sa.Column("match_id", sa.Integer(), sa.ForeignKey("matches.id"), nullable=False),
        sa.Column("env", sa.String(100), nullable=False),
        sa.Column("n_seats", sa.Integer(), nullable=False),
        sa.Column("seed", sa.BigInteger(), nullable=False),
        sa.Column("length", sa.Integer(), nullable=False),
        sa.Column("truncated", sa.Boolean(), nullable=False),
        sa.Column("created_at", sa.DateTime(), nullable=False),
        sa.Column("actions", sa.LargeBinary(), nullable=True),
    )
    op.create_index("ix_games_match_id", "games", ["match_id"])
    op.create_index("ix_games_env_id", "games", ["env", "id"])
    op.create_table(
        "game_seats",
        sa.Column("game_id", sa.Integer(), sa.ForeignKey("games.id", ondelete="CASCADE"), primary_key=True),
        sa.Column("seat", sa.Integer(), primary_key=True),
        sa.Column("player_id", sa.Integer(), sa.ForeignKey("players.id"), nullable=False),
        sa.Column("score", sa.Float(), nullable=False),
        sa.Column("points", sa.Float(), nullable=False),
    )
    op.create_index("ix_game_seats_player_game", "game_seats", ["player_id", "game_id"])

"""seed ranges

The table of the seeds taken for a pair's games before they are played (``seed_ranges``), each range the pair's
``seq``-th under a unique ``(lo, hi, seq)``: the same tournament queued twice, or by two users at once, plays and
stores each game once.
"""

import sqlalchemy as sa
from alembic import op

revision = "0004"
down_revision = "0003"
branch_labels = None
depends_on = None


def upgrade() -> None:
    """Create ``seed_ranges``."""
    op.create_table(
        "seed_ranges",
        sa.Column("id", sa.Integer(), primary_key=True),
        sa.Column("lo", sa.Integer(), sa.ForeignKey("players.id"), nullable=False),
        sa.Column("hi", sa.Integer(), sa.ForeignKey("players.id"), nullable=False),
        sa.Column("seq", sa.Integer(), nullable=False),
        sa.Column("first_seed", sa.BigInteger(), nullable=False),
        sa.Column("rounds", sa.BigInteger(), nullable=False),
        sa.Column("games", sa.BigInteger(), nullable=False),
        sa.Column("variant", sa.String(64), nullable=False),
        sa.Column("owner", sa.String(200), nullable=False),
        sa.Column("job_id", sa.Integer(), sa.ForeignKey("jobs.id"), nullable=True),
        sa.Column("created_at", sa.DateTime(), nullable=False),
        sa.UniqueConstraint("lo", "hi", "seq", name="uq_seed_ranges_pair_seq"),
    )
    op.create_index("ix_seed_ranges_job_id", "seed_ranges", ["job_id"])

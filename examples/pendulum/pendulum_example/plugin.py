"""Hook implementations of the pendulum example (cheap to import: names only)."""

from physinfer.hooks import hookimpl

"""Hook implementations of the hanging-cloth plugin (cheap to import: names only)."""

from physinfer.hooks import hookimpl

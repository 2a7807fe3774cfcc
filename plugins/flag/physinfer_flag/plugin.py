"""Hook implementations of the flag plugin (cheap to import: names only)."""

from physinfer.hooks import hookimpl

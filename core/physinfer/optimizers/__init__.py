"""Built-in optimizers behind :class:`physinfer.roles.Optimizer`: ``ax``, ``random``, ``cma``.

Each is imported only when chosen (see :mod:`physinfer.builtins`).
"""

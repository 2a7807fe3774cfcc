"""A damped pendulum: the worked example of a physinfer phenomenon plugin."""

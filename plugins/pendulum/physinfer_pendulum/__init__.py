"""The pendulum: a bob on a string, measured from real footage (a phone video, a classroom film)."""

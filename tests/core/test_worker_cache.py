"""One cache of worker-built models for every workflow (issue 47): per thread, per kind."""

import threading

from physinfer.worker_cache import thread_cached


def test_a_model_is_built_once_per_thread_kind_and_key():
    built = []

    def build(tag):
        built.append(tag)
        return object()

    first = thread_cached("test.a", 1, lambda: build("a1"))
    assert thread_cached("test.a", 1, lambda: build("again")) is first
    other_kind = thread_cached("test.b", 1, lambda: build("b1"))  # the same key under another kind
    assert other_kind is not first
    seen = []
    worker = threading.Thread(target=lambda: seen.append(thread_cached("test.a", 1, lambda: build("a1 there"))))
    worker.start()
    worker.join()
    assert seen[0] is not first  # another thread builds its own (EGL contexts belong to a thread)
    assert built == ["a1", "b1", "a1 there"]


def test_only_latest_keeps_one_model_and_closes_those_it_drops():
    closed = []
    one = thread_cached("test.latest", "x", lambda: ["x"], only_latest=True, close=closed.append)
    assert thread_cached("test.latest", "x", lambda: ["new x"], only_latest=True, close=closed.append) is one
    thread_cached("test.latest", "y", lambda: ["y"], only_latest=True, close=closed.append)
    assert closed == [["x"]]
    assert thread_cached("test.latest", "x", lambda: ["x again"], only_latest=True, close=closed.append) == ["x again"]
    assert closed == [["x"], ["y"]]

"""CappedLog.wait_for: a finished process's output is read to its end while it comes, and given up on, said so in
the log, when it stops coming (tests/test_docker.py reads a slowed engine stream through a real container)."""

import threading

from runner.backends.logcap import CappedLog


def _reader(log: CappedLog, release: threading.Event) -> threading.Thread:
    def read() -> None:
        log.write(b"first line\n")
        release.wait()  # a stream that hangs until the test lets it go
        log.write(b"the rest\n")

    t = threading.Thread(target=read, daemon=True)
    t.start()
    return t


def test_a_stream_that_stops_coming_is_given_up_on_and_the_log_says_so(tmp_path):
    log = CappedLog(tmp_path / "log.txt", 2**20)
    release = threading.Event()
    reader = _reader(log, release)
    assert log.wait_for(reader, stall_s=0.3) is False
    log.close()
    release.set()
    reader.join(timeout=5)
    text = (tmp_path / "log.txt").read_text()
    assert text == "first line\n\n[slamrun: nothing came for 0.3 s after the process ended; the rest is lost]\n"
    assert log.received == len(b"first line\n") + len(b"the rest\n")  # drained, not written


def test_a_stream_read_to_its_end_leaves_no_note(tmp_path):
    log = CappedLog(tmp_path / "log.txt", 2**20)
    release = threading.Event()
    release.set()
    reader = _reader(log, release)
    assert log.wait_for(reader, stall_s=30) is True
    log.close()
    log.close()  # a second close changes nothing
    assert (tmp_path / "log.txt").read_text() == "first line\nthe rest\n"

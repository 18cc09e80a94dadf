"""One atomic writer for every file a run rewrites (geogrid_dem.rundir.write_atomic): threads
and processes that write the same file at once leave one whole version, and no temporary."""

import threading

from geogrid_dem.rundir import _files, is_temporary, write_atomic


def test_threads_writing_one_file_leave_one_whole_version_and_no_temporary(tmp_path):
    path = tmp_path / "study.csv"
    texts = [f"{k}\n" * 2000 for k in range(8)]

    def writer(text):
        for _ in range(25):
            write_atomic(path, text)

    threads = [threading.Thread(target=writer, args=(t,)) for t in texts]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert path.read_text() in texts
    assert [p.name for p in tmp_path.iterdir()] == ["study.csv"]


def test_a_temporary_left_by_a_killed_writer_is_not_a_result(tmp_path):
    (tmp_path / "rows").mkdir()
    left = tmp_path / "rows" / ".a.json.123.456.tmp"
    left.write_text("{")
    (tmp_path / "rows" / "a.json").write_text("{}")
    assert is_temporary(left) and not is_temporary(tmp_path / "rows" / "a.json")
    assert [p.name for p in _files(tmp_path)] == ["a.json"]

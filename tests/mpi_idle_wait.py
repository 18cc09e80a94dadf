"""Run by tests/test_hierarchical_mpi.py as ``mpiexec -n 2 python tests/mpi_idle_wait.py OUT``:
the CPU time rank 1 spends waiting while rank 0 works for WORK_S seconds, once at a plain
``comm.bcast`` and once through ``femcoupling.fem.mpi_points`` (``on_root`` and
``bcast_from_root``). Rank 0 writes OUT/result.json."""

import json
import sys
import time

WORK_S = 1.0


def main(out: str) -> None:
    from femcoupling.fem.mpi_points import bcast_from_root, on_root, world

    comm = world()

    def waited(wait) -> tuple:
        """(CPU s, start, end, value). The start and end are CLOCK_MONOTONIC readings, one
        clock for every process of this machine, so the test measures rank 1's wait from the
        moment rank 0 began its work: the ranks leave the barrier up to a scheduler slice
        apart, and rank 1's own start can be later than rank 0's."""
        comm.barrier()
        c0, t0 = time.process_time(), time.clock_gettime(time.CLOCK_MONOTONIC)
        got = wait()
        return time.process_time() - c0, t0, time.clock_gettime(time.CLOCK_MONOTONIC), got

    def work():
        time.sleep(WORK_S)
        return 42

    plain = waited(lambda: comm.bcast(work() if comm.rank == 0 else None, root=0))
    made = waited(lambda: on_root(comm, work))
    sent = waited(lambda: bcast_from_root(comm, work() if comm.rank == 0 else None))
    rows = comm.gather({"plain": plain, "on_root": made, "bcast_from_root": sent}, root=0)
    if comm.rank == 0:
        with open(f"{out}/result.json", "w") as fh:
            json.dump({"ranks": comm.size, "work_s": WORK_S, "ranks_rows": rows}, fh)
    print(f"on {comm.size} rank(s): done", flush=True)


if __name__ == "__main__":
    main(sys.argv[1])

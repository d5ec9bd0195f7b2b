"""The player benchmark behind ``jaxcnc bench player``: table playback into sinks, memory on a long table."""

from __future__ import annotations

import numpy as np


def run_player_benchmarks(seconds: float = 60.0, rates: tuple[float, ...] = (10_000.0, 100_000.0)) -> dict:
    """Play synthetic 3-axis tables of ``seconds`` into ``sim`` and into the TCP receiver process, each rate
    twice: positions only, and with a laser power channel (a value per tick, as every planned table has since
    table format 2 — the stream then carries the power of every row too).

    Prints ticks/s and the multiple of real time, and the player's peak memory growth (the table is
    memory-mapped and streamed, so it stays far below the table's size).
    """
    import subprocess
    import sys
    import tempfile
    from pathlib import Path

    from jaxcnc.format import TableFile, TableWriter
    from jaxcnc.hw.player import play
    from jaxcnc.hw.receiver import spawn
    from jaxcnc.hw.sinks.sim import SimSink
    from jaxcnc.hw.sinks.stream import StreamSink

    out: dict = {}
    print(f"jaxcnc bench (player): {seconds:g} s 3-axis tables")
    with tempfile.TemporaryDirectory() as tmp:
        for hz, lit in [(hz, lit) for hz in rates for lit in (False, True)]:
            n = int(seconds * hz)
            path = Path(tmp) / f"t{int(hz)}{'-power' if lit else ''}.ticks"
            with TableWriter(path, axes=["x", "y", "z"], tick_hz=hz, discrete_mm=0.001, n_rows=n, power=lit) as w:
                chunk = 1 << 20
                for first in range(0, n, chunk):
                    k = np.arange(first, min(n, first + chunk))
                    p = np.stack([k % 100_000, (k // 7) % 50_000, np.zeros_like(k)], axis=1).astype(np.int32)
                    power = ((k // 1000) % 2 * 0.5 + (k % 1000) / 2000.0).astype(np.float32) if lit else None
                    w.write(p, np.zeros_like(p), power)
            size_mb = path.stat().st_size / 2**20
            table = TableFile(path)
            res = play(table, SimSink(buffer_rows=65536, keep=False), chunk_rows=65536)
            # memory of a fresh process that opens (verifies) and plays the table into sim: anonymous memory
            # stays bounded; the memory-mapped file's pages are page cache the kernel can drop
            code = (
                "import sys; from jaxcnc.format import TableFile; from jaxcnc.hw.player import play; "
                "from jaxcnc.hw.sinks.sim import SimSink; "
                "play(TableFile(sys.argv[1]), SimSink(buffer_rows=65536, keep=False), chunk_rows=65536); "
                "st = dict(l.split(':', 1) for l in open('/proc/self/status')); "
                "print(int(st['RssAnon'].split()[0]) / 1024, int(st['VmHWM'].split()[0]) / 1024)"
            )
            anon, hwm = map(
                float,
                subprocess.run(
                    [sys.executable, "-c", code, str(path)], capture_output=True, text=True, check=True
                ).stdout.split(),
            )
            what = "with a power channel" if lit else "positions only"
            print(
                f"  {hz / 1000:g} kHz, {what}, {n:,} rows ({size_mb:.0f} MB file): sim {n / res.wall_s:,.0f} ticks/s = "
                f"{res.real_time_factor:,.0f}x real time; player process: {anon:.0f} MB anonymous memory "
                f"(peak resident {hwm:.0f} MB incl. mapped file pages)"
            )
            proc, addr = spawn("tcp://127.0.0.1:0", "--speed", "1e6", "--capacity", "65536")
            try:
                res_tcp = play(table, StreamSink(addr), chunk_rows=65536)
                proc.communicate(timeout=120)
            finally:
                proc.kill()
            print(
                f"    tcp receiver (loopback, other process): {n / res_tcp.wall_s:,.0f} ticks/s = "
                f"{res_tcp.real_time_factor:,.1f}x real time"
            )
            out[f"{hz:g}{'-power' if lit else ''}"] = {
                "sim_ticks_s": n / res.wall_s,
                "tcp_ticks_s": n / res_tcp.wall_s,
                "anon_mb": anon,
                "peak_resident_mb": hwm,
                "file_mb": size_mb,
            }
    return out

"""``halstreamer``: play a table through a real LinuxCNC HAL (package ``linuxcnc-uspace``).

The sink starts its own HAL session and wires, in one servo thread running at the table's tick
rate (or ``period_ns``)::

    halstreamer (this process feeds its stdin)
        → streamer.0   pins: one s32 per axis (discretes), a float for the laser power, a bit for the
                       laser enable (power > 0) and a bit for pulses (work/PSO pulses, one tick wide)
        → sampler.0    the same pins plus streamer.0.underruns, recorded only on ticks where
                       the streamer delivered fresh data (enable = run AND NOT streamer.0.empty)
        → halsampler   (its stdout comes back to this process line by line)

The sampler is the drives' acknowledgement: every line it returns is one tick executed, so
``executed_tick`` counts them and ``free_rows`` is the streamer's FIFO depth less the rows sent
and not yet executed (credit-based flow control — the FIFO never overflows and nothing blocks).
The streamer is held (``run`` = 0) until half its FIFO is filled, so the first rows cannot run dry.

Underruns: the stock ``streamer`` holds its pins when its FIFO runs empty (it cannot ramp down
along the path — that needs a controller-side component, as the ``sim`` sink and the stream
receiver have). The sampled ``underruns`` column tells how many ticks were missed *inside* the
job; :attr:`underruns` reports them after ``close``.

As root, LinuxCNC's ``rtapi_app`` drops to ``RTAPI_UID`` (the sink uses the first ordinary user,
or ``nobody``) and listens on the socket ``RTAPI_FIFO_PATH`` (the sink puts it in a private
directory that user can write). One HAL session runs per machine: the sink takes a machine-wide
lock (``flock`` on ``LOCK_PATH``) before it looks for a running session and holds it until the
session has ended, so two players can never both start one; it refuses to start if one is running
already (``halrun -U`` ends one that was not started by jaxcnc).

The laser (``docs/laser.md``): power, enable and pulse pass a gate that is open only while the streamer
delivers fresh rows and ``laser-enable`` is set — the laser is dark on the very tick an underrun begins
(the streamer holds its pins then; the gate does not hold the beam), and on an abort (the player's error or
a signal) ``laser-enable`` is cleared at once and the streamer is disabled: the drives hold the last executed
row. The gated outputs are the nets ``laser-power`` (float), ``laser-on`` and ``laser-pulse`` (bits) for the
machine's HAL to drive the source with; the sampler records them beside the positions.
"""

from __future__ import annotations

import os
import pwd
import shutil
import subprocess
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

from jaxcnc.errors import JaxcncError
from jaxcnc.format import EventKind, TableHeader
from jaxcnc.hw.sinks.record import RowRecorder

REALTIME = "/usr/lib/linuxcnc/realtime"
#: held (flock) by the process whose sink runs the machine's HAL session: the guard against a second one
LOCK_PATH = os.path.join(tempfile.gettempdir(), "jaxcnc-hal.lock")
TOOLS = ("halcmd", "halstreamer", "halsampler")
#: System V keys of the FIFOs of streamer.0 ('HST0') and sampler.0 ('HSA0')
STREAM_KEYS = ("0x48535430", "0x48534130")


def hal_available() -> str | None:
    """``None`` if LinuxCNC's HAL tools are installed, else what is missing."""
    missing = [t for t in TOOLS if shutil.which(t) is None]
    if not os.path.exists(REALTIME):
        missing.append(REALTIME)
    return (
        f"LinuxCNC is not installed (missing {', '.join(missing)}; apt-get install linuxcnc-uspace)"
        if missing
        else None
    )


def _rtapi_uid() -> int:
    """The ordinary user rtapi_app runs as when started by root."""
    if "RTAPI_UID" in os.environ:
        return int(os.environ["RTAPI_UID"])
    users = sorted(p.pw_uid for p in pwd.getpwall() if 1000 <= p.pw_uid < 60000)
    return users[0] if users else pwd.getpwnam("nobody").pw_uid


def hal_config(n_axes: int, depth: int, period_ns: int) -> str:
    """The HAL file: streamer → sampler (gated on fresh data), the laser through a gate, one servo thread."""
    n = n_axes
    cfg = "s" * n + "fbb"
    lines = [
        f"loadrt threads name1=servo period1={period_ns}",
        f"loadrt streamer depth={depth} cfg={cfg}",
        f"loadrt sampler depth={4 * depth} cfg={cfg}s",
        "loadrt not count=1",
        "loadrt and2 count=4",
        "loadrt mux2 count=1",
        "addf streamer.0 servo",
        "addf not.0 servo",
        "addf and2.0 servo",
        "addf and2.1 servo",
        "addf and2.2 servo",
        "addf and2.3 servo",
        "addf mux2.0 servo",
        "addf sampler.0 servo",
        "net run streamer.0.enable and2.0.in0",
        "net empty streamer.0.empty not.0.in",
        "net fresh not.0.out and2.0.in1 and2.1.in0",
        "net record and2.0.out sampler.0.enable",
        "sets run 0",
        # the laser gate: open while rows are fresh and laser-enable is set (the sink clears it on an abort)
        "net laser-enable and2.1.in1",
        "sets laser-enable 1",
        "net laser-gate and2.1.out mux2.0.sel and2.2.in1 and2.3.in1",
        f"net laser-cmd streamer.0.pin.{n} mux2.0.in1",
        f"net laser-power mux2.0.out sampler.0.pin.{n}",
        f"net laser-on-cmd streamer.0.pin.{n + 1} and2.2.in0",
        f"net laser-on and2.2.out sampler.0.pin.{n + 1}",
        f"net laser-pulse-cmd streamer.0.pin.{n + 2} and2.3.in0",
        f"net laser-pulse and2.3.out sampler.0.pin.{n + 2}",
    ]
    lines += [f"net col{k} streamer.0.pin.{k} sampler.0.pin.{k}" for k in range(n)]
    lines += [f"net underruns streamer.0.underruns sampler.0.pin.{n + 3}", "start"]
    return "\n".join(lines) + "\n"


class HalStreamerSink:
    """Plays into LinuxCNC's streamer; after ``close``, ``recorded`` holds what the sampler saw.

    ``depth``: the streamer's FIFO in rows. ``period_ns``: the servo period (default: the table's
    tick). ``record``: a ``.npy`` file for the sampled positions (else kept in memory when small).
    ``timeout_s``: how long the sink waits for HAL to make progress before it gives up.
    """

    def __init__(
        self,
        depth: int = 8192,
        period_ns: int | None = None,
        record: str | Path | None = None,
        keep: bool | None = None,
        timeout_s: float = 10.0,
    ):
        problem = hal_available()
        if problem:
            raise JaxcncError(f"halstreamer sink: {problem}")
        self.depth, self.period_ns, self.keep, self.timeout_s = depth, period_ns, keep, timeout_s
        self.record_path = Path(record) if record else None
        self.recorded: np.ndarray | None = None
        self.laser_power: np.ndarray | None = None  # after close: the laser column as sampled (if kept)
        self.laser_on: np.ndarray | None = None  # after close: the enable bit as sampled (if kept)
        self.laser_pulse: np.ndarray | None = None  # after close: the pulse bit as sampled (if kept)
        self.underruns = 0  # ticks the streamer found its FIFO empty between the first and the last row
        self._sent = 0
        self._executed = 0
        self._laser = 0.0
        self._running = False
        self._cond = threading.Condition()
        self._error: str | None = None
        self._first_underruns: int | None = None
        self._procs: list[subprocess.Popen] = []
        self._hal_up = False
        self._lock_fd: int | None = None
        self.laser_at_end: float | None = None  # after an abort: the laser output HAL reports

    # ---- HAL session -------------------------------------------------------------------------
    def _env(self) -> dict:
        env = dict(os.environ)
        self._tmp = tempfile.mkdtemp(prefix="jaxcnc-hal-")
        if os.geteuid() == 0:
            os.chmod(self._tmp, 0o777)  # rtapi_app binds its socket here after dropping to RTAPI_UID
            env.setdefault("RTAPI_UID", str(_rtapi_uid()))
            env["RTAPI_FIFO_PATH"] = os.path.join(self._tmp, "rtapi.sock")
        return env

    def _run(self, *cmd: str) -> tuple[int, str]:
        """Run a HAL tool; its output goes through a file, not a pipe: ``halcmd loadrt`` starts
        ``rtapi_app``, which would hold a pipe open for as long as the session lives."""
        with tempfile.TemporaryFile(dir=self._tmp) as out:
            rc = subprocess.run(cmd, env=self._hal_env, stdout=out, stderr=subprocess.STDOUT, timeout=60).returncode
            out.seek(0)
            text = out.read().decode(errors="replace")
        lines = [ln for ln in text.splitlines() if "fallback_uid" not in ln and "POSIX non-realtime" not in ln]
        return rc, "\n".join(lines).strip()

    def _remove_stale_fifos(self) -> None:
        """Remove streamer/sampler FIFOs a killed session left behind (``halrun -U`` leaves them).

        Their System V segments outlive the session; a new streamer of another depth or width then
        fails with ``shmget: Invalid argument``. Only unattached segments of channel 0 are removed.
        """
        if shutil.which("ipcs") is None or shutil.which("ipcrm") is None:
            return
        rc, text = self._run("ipcs", "-m")
        for line in text.splitlines() if rc == 0 else []:
            f = line.split()
            if len(f) >= 6 and f[0].lower() in STREAM_KEYS and f[5] == "0":
                self._run("ipcrm", "-m", f[1])

    def _halcmd(self, *args: str) -> None:
        rc, text = self._run("halcmd", *args)
        if rc != 0:
            raise JaxcncError(f"halstreamer sink: halcmd {' '.join(args)} failed: {text}")

    def _lock(self) -> None:
        """Take the machine-wide session lock, or refuse: two sinks can never both find no session
        running and both start one (the check and the start happen under the lock)."""
        import fcntl

        fd = os.open(LOCK_PATH, os.O_RDWR | os.O_CREAT, 0o666)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            raise JaxcncError(
                "halstreamer sink: a LinuxCNC realtime session is already running (another jaxcnc play)"
            ) from None
        self._lock_fd = fd

    def _unlock(self) -> None:
        fd, self._lock_fd = self._lock_fd, None
        if fd is not None:
            os.close(fd)  # releases the flock

    def open(self, header: TableHeader) -> None:
        self.header = header
        n = header.n_axes
        self._ncols = n + 4
        self._lock()
        self._hal_env = self._env()
        if self._run(REALTIME, "status")[0] == 0:
            shutil.rmtree(self._tmp, ignore_errors=True)
            self._unlock()
            raise JaxcncError("halstreamer sink: a LinuxCNC realtime session is already running (end it: halrun -U)")
        self._remove_stale_fifos()
        period = self.period_ns or round(1e9 / header.tick_hz)
        rc, text = self._run(REALTIME, "start")
        if rc != 0:
            shutil.rmtree(self._tmp, ignore_errors=True)
            self._unlock()
            raise JaxcncError(f"halstreamer sink: LinuxCNC realtime did not start: {text}")
        self._hal_up = True
        try:
            cfg = Path(self._tmp) / "jaxcnc.hal"
            cfg.write_text(hal_config(n, self.depth, period))
            self._halcmd("-f", str(cfg))
            keep = self.keep or (self.keep is None and header.n_rows * n * 4 <= 256 << 20)
            self._rec = RowRecorder(n, self.record_path, keep=keep)
            self._laser_rows: list[np.ndarray] | None = [] if keep else None
            # stdbuf: halsampler's stdout is a pipe; line buffering makes every executed tick come back at once
            sampler = (
                ["stdbuf", "-oL", "halsampler", "-c", "0"] if shutil.which("stdbuf") else ["halsampler", "-c", "0"]
            )
            self._sampler = subprocess.Popen(sampler, env=self._hal_env, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
            self._streamer = subprocess.Popen(
                ["halstreamer", "-c", "0"], env=self._hal_env, stdin=subprocess.PIPE, stderr=subprocess.PIPE
            )
            self._procs = [self._sampler, self._streamer]
            self._reader = threading.Thread(target=self._read_samples, daemon=True)
            self._reader.start()
        except BaseException:
            self._shutdown()
            raise

    def _read_samples(self) -> None:
        """Count (and record) the ticks the sampler returns."""
        rest = b""
        out = self._sampler.stdout
        while True:
            chunk = out.read1(1 << 16)
            if not chunk:
                break
            data = rest + chunk
            cut = data.rfind(b"\n") + 1
            rest = data[cut:]
            if cut == 0:
                continue
            try:
                vals = np.array(data[:cut].split(), dtype=np.float64).reshape(-1, self._ncols)
            except ValueError:
                with self._cond:
                    self._error = f"halsampler returned a malformed line near tick {self._executed}"
                    self._cond.notify_all()
                return
            k, m = self._executed, vals.shape[0]
            if k + m > self._sent:
                with self._cond:
                    self._error = f"HAL executed {k + m} ticks, more than the {self._sent} sent"
                    self._cond.notify_all()
                return
            self._rec.append(vals[:, :-4].astype(np.int32))
            if self._laser_rows is not None:
                self._laser_rows.append(vals[:, -4:-1])
            u = vals[:, -1]
            if self._first_underruns is None:
                self._first_underruns = int(u[0])
            with self._cond:
                self.underruns = int(u[-1]) - self._first_underruns
                self._executed = k + m
                self._cond.notify_all()

    # ---- the sink protocol ---------------------------------------------------------------------
    @property
    def crc(self) -> int:
        """CRC-32 of the sampled positions, in order."""
        return self._rec.crc

    def free_rows(self) -> int:
        self._check()
        return max(0, self.depth - (self._sent - self._executed))

    def _laser_column(self, first_tick: int, m: int, events: np.ndarray) -> np.ndarray:
        """Laser power on each of the ``m`` rows from ``first_tick`` (held between LASER events)."""
        laser = events[events["kind"] == EventKind.LASER]
        if laser.size == 0:
            return np.full(m, self._laser)
        last = np.searchsorted(laser["tick"] - first_tick, np.arange(m), side="right") - 1  # latest event per row
        power = np.where(last >= 0, laser["value"][np.maximum(last, 0)], self._laser)
        self._laser = float(laser["value"][-1])
        return power

    def write(self, first_tick: int, rows: np.ndarray, events: np.ndarray, power: np.ndarray | None = None) -> None:
        """Queue rows with the laser: ``power`` per row (else held from the LASER events), the enable bit
        (power > 0) and the pulse bit (1 on the tick of each work or PSO pulse event)."""
        if first_tick != self._sent:
            raise RuntimeError(f"halstreamer sink: expected tick {self._sent}, got {first_tick}")
        m = rows.shape[0]
        if m > self.free_rows():
            raise RuntimeError("halstreamer sink: FIFO overflow (the player ignored flow control)")
        if power is None:
            power = self._laser_column(first_tick, m, events)
        power = np.asarray(power, np.float64)
        pulse = np.zeros(m, np.int64)
        pulses = events[np.isin(events["kind"], (EventKind.WORK_PULSE, EventKind.PSO_PULSE))]
        pulse[pulses["tick"] - first_tick] = 1
        fmt = " ".join(["%d"] * rows.shape[1] + ["%.9g", "%d", "%d"]) + "\n"
        cols = [rows.astype(np.int64), power, (power > 0).astype(np.int64), pulse]
        flat = np.column_stack(cols).astype(object).ravel()
        text = ((fmt * m) % tuple(flat)).encode()
        # counted as sent before they reach the FIFO: once written, HAL may execute them and the sampler thread
        # report them before this thread runs again, and it checks "executed <= sent" (a failed write ends the
        # sink anyway)
        self._sent += m
        try:
            self._streamer.stdin.write(text)
            self._streamer.stdin.flush()
        except BrokenPipeError:
            raise JaxcncError(f"halstreamer sink: halstreamer exited ({self._stderr(self._streamer)})") from None
        if not self._running and (self._sent >= self.depth // 2 or self._sent == self.header.n_rows):
            self._start()

    def _start(self) -> None:
        self._halcmd("sets", "run", "1")
        self._running = True

    def wait(self) -> None:
        if not self._running:
            self._start()
        self._wait_for(self._executed + 1)

    def _wait_for(self, count: int) -> None:
        """Block until ``count`` ticks have executed; fail if HAL makes no progress for ``timeout_s``."""
        deadline = time.monotonic() + self.timeout_s
        with self._cond:
            seen = self._executed
            while self._executed < count and self._error is None:
                if self._executed != seen:  # progress: the stall clock restarts
                    seen, deadline = self._executed, time.monotonic() + self.timeout_s
                left = deadline - time.monotonic()
                if left <= 0 or self._sampler.poll() is not None:
                    break
                self._cond.wait(min(left, 0.1))
        self._check()
        if self._executed < count:
            raise JaxcncError(
                f"halstreamer sink: HAL stopped executing (tick {self._executed} of {self._sent} sent; "
                f"{self._stderr(self._sampler)})"
            )

    def _check(self) -> None:
        if self._error:
            raise JaxcncError(f"halstreamer sink: {self._error}")

    @staticmethod
    def _stderr(proc: subprocess.Popen) -> str:
        if proc.poll() is None:
            return "still running"
        err = proc.stderr.read().decode(errors="replace").strip() if proc.stderr else ""
        return f"exit {proc.returncode}: {err}" if err else f"exit {proc.returncode}"

    def executed_tick(self) -> int:
        return self._executed - 1

    def close(self) -> None:
        try:
            if self._procs:
                if not self._running and self._sent:
                    self._start()
                self._streamer.stdin.close()
                self._wait_for(self._sent)
                self.recorded = self._rec.close()
                self._laser_columns()
        finally:
            self._shutdown()

    def abort(self) -> None:
        """Stop now: the laser gate closed at once, the streamer disabled (the stock streamer cannot
        ramp: the drives hold the last executed row — on the path, at rest), the sampled rows kept;
        then the session ends. Never raises."""
        try:
            if self._hal_up and self._procs:
                self._run("halcmd", "sets", "laser-enable", "0")
                self._run("halcmd", "sets", "run", "0")
                rc, text = self._run("halcmd", "getp", "mux2.0.out")
                try:
                    self.laser_at_end = float(text.split()[-1]) if rc == 0 else None
                except (ValueError, IndexError):
                    self.laser_at_end = None
                self._settle()
                self._stop_procs()
                self._reader.join(2.0)
                self.recorded = self._rec.close()
                self._laser_columns()
        except Exception:  # noqa: BLE001 - best effort: the session is ended below in any case
            pass
        finally:
            self._shutdown()

    def _laser_columns(self) -> None:
        """Split the sampled laser columns into power, enable and pulse (when kept)."""
        if self._laser_rows is not None:
            cols = np.concatenate(self._laser_rows) if self._laser_rows else np.zeros((0, 3))
            self.laser_power, self.laser_on, self.laser_pulse = cols[:, 0], cols[:, 1] > 0, cols[:, 2] > 0

    def _settle(self, quiet_s: float = 0.2, limit_s: float = 2.0) -> None:
        """Wait until the samples already taken have come back (no new one for ``quiet_s``)."""
        end = time.monotonic() + limit_s
        with self._cond:
            seen = self._executed
            while time.monotonic() < end:
                self._cond.wait(quiet_s)
                if self._executed == seen:
                    return
                seen = self._executed

    def _stop_procs(self) -> None:
        for p in self._procs:
            if p.poll() is None:
                p.terminate()
                try:
                    p.wait(5)
                except subprocess.TimeoutExpired:
                    p.kill()
                    p.wait()
        self._procs = []

    def _shutdown(self) -> None:
        self._stop_procs()
        if self._hal_up:
            self._run("halcmd", "unload", "all")
            self._run(REALTIME, "stop")
            self._remove_stale_fifos()
            self._hal_up = False
        if getattr(self, "_tmp", None):
            shutil.rmtree(self._tmp, ignore_errors=True)
        self._unlock()

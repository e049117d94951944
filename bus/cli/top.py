"""``sonibus top``: a live terminal view of the show — robots, nodes, the selected
robot's joints, the last events — drawn from ``bus/monitor.py``'s ``Monitor``, so
it reads only the bus and runs on any machine.

Keys: ``s`` stops every robot (``y`` confirms, any other key cancels; each reply
is listed with the events), tab or up/down select the robot, ``q`` quits (exit 0),
Ctrl-C or SIGINT/SIGTERM end it as every command (130). docs/top.md shows it.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import signal
import sys
import threading
import time
from collections.abc import Iterable, Sequence
from typing import Any, ClassVar

from rich.text import Text
from textual import events
from textual.app import App, ComposeResult
from textual.binding import Binding, BindingType
from textual.containers import Horizontal, Vertical
from textual.screen import ModalScreen
from textual.widgets import DataTable, Footer, Static

from .. import connection
from ..busconfig import BusConfig
from ..claimwatch import owners
from ..client import Outcome, stop_all
from ..errors import CommandError, ConfigError, SonibusError
from ..monitor import Monitor
from ..text import printable
from ..views import EventView, JointView, NodeView, RobotView, Snapshot
from .api import Command, Environment, Exit, bus_config, joined
from .hints import reach_hint_now

EVERY_S = 0.25         # the view is redrawn this often
STOP_TIMEOUT_S = 5.0   # a robot's answer to stop
BAR = 20               # characters of a joint's bar
SPARK_SPAN = 0.25      # the smallest range a sparkline spreads over, of a joint's limits
SPARK_MIN = 6          # characters of sparkline before the bar is given room
SPARKS = "▁▂▃▄▅▆▇█"
LONELY_S = 3.0         # with no node on the bus for this long, the status line says whom top reached
ALARM, WARNING, GONE = "bold red", "bold yellow", "red"

NARROW = 120           # a terminal narrower than this (80×24) has its events below the joints, its tables compact
EVENTS_MIN = 4         # rows the events keep below the joints (their border and three lines)

ROBOT_COLUMNS = ("robot", "owner", "model", "frames/s", "latency", "seq gaps", "state")
NODE_COLUMNS = ("adapter", "host", "node", "uptime", "state", "rx/s", "tx/s", "dropped", "stale", "bad", "errors")
NARROW_NODE_COLUMNS = ("adapter", "node", "up", "state", "rx/s", "tx/s", "drop", "stale", "bad", "err")  # (host/node)


class Nodes(DataTable[Text], can_focus=False):
    """The nodes table: shown, never focused (up/down belong to the robots)."""


class ConfirmStop(ModalScreen[bool]):
    """``y`` stops every robot; any other key cancels."""

    DEFAULT_CSS = """
    ConfirmStop { align: center middle; }
    ConfirmStop > Static { width: auto; max-width: 90%; border: heavy red; padding: 1 2; background: $panel; }
    """

    def __init__(self, robots: Sequence[str]) -> None:
        super().__init__()
        self.robots = robots

    def compose(self) -> ComposeResult:
        yield Static(Text.assemble(("Stop every robot", ALARM), f" ({printable(', '.join(self.robots))})?\n\n",
                                   ("y", "bold"), " stop them    ", ("any other key", "bold"), " cancel"))

    def on_key(self, event: events.Key) -> None:
        event.stop()
        self.dismiss(event.key == "y")


class TopApp(App[int]):
    """The view: ``monitor``'s snapshot redrawn every ``every_s``; with ``signals``,
    SIGINT and SIGTERM end it (the command's process; tests drive it with a pilot)."""

    TITLE = "sonibus top"
    CSS = """
    #robots { height: auto; max-height: 10; }
    #nodes { height: auto; max-height: 14; }
    #below { height: 1fr; }
    #joints { width: 3fr; padding-right: 2; border-top: solid $accent; text-wrap: nowrap; text-overflow: clip; }
    #events { width: 2fr; min-width: 40; border-top: solid $accent; }
    #below.narrow { layout: vertical; }
    #below.narrow #joints { width: 1fr; height: auto; padding-right: 0; }
    #below.narrow #events { width: 1fr; min-width: 0; height: 1fr; min-height: 3; }
    #event-lines { text-wrap: nowrap; text-overflow: ellipsis; }
    #status { height: auto; max-height: 3; color: $text-muted; }
    """
    BINDINGS: ClassVar[list[BindingType]] = [
        Binding("s", "stop_all", "stop every robot"),
        Binding("q", "quit_top", "quit"),
        Binding("tab", "next_robot(1)", "next robot", priority=True),
        Binding("shift+tab", "next_robot(-1)", "previous robot", show=False, priority=True),
        Binding("ctrl+c", "interrupt", show=False, priority=True),
    ]

    def __init__(self, monitor: Monitor, every_s: float = EVERY_S, signals: bool = False,
                 bus_config: BusConfig | None = None) -> None:
        super().__init__()
        self.monitor, self.every_s, self.signals = monitor, every_s, signals
        self.bus_config = bus_config  # (given: with no node listed, the status line says whom top reached)
        self.snapshot = monitor.snapshot()
        self.selected: str | None = None
        self.reach = ""  # why no node is listed: whom top's session reached (found on a thread)
        self._lonely_since = time.monotonic()
        self._reaching: threading.Thread | None = None

    def compose(self) -> ComposeResult:
        self.robots = DataTable[Text](id="robots", cursor_type="row", zebra_stripes=True)
        self.nodes = Nodes(id="nodes", cursor_type="none", zebra_stripes=True)
        self.joints, self.events = Static(id="joints"), Vertical(id="events")
        self.event_lines, self.status = Static(id="event-lines"), Static(id="status")
        self.below = Horizontal(id="below")
        yield self.robots
        yield self.nodes
        with self.below:
            yield self.joints
            with self.events:
                yield self.event_lines
        yield self.status
        yield Footer()

    def on_mount(self) -> None:
        for name in ROBOT_COLUMNS:
            self.robots.add_column(name, key=name)
        self.narrow: bool | None = None  # (the nodes' columns are made for the width at the first redraw)
        self.robots.focus()
        self.events.border_title = "events"
        owners(self.monitor.bus)  # the claims, followed from now: those a stop reports as silent
        if self.signals:
            loop = asyncio.get_running_loop()
            for sig in (signal.SIGINT, signal.SIGTERM):
                loop.add_signal_handler(sig, self.exit, int(Exit.INTERRUPTED))
        self.redraw()
        self.set_interval(self.every_s, self.redraw)

    def check_action(self, action: str, parameters: tuple[object, ...]) -> bool | None:
        """While the stop is asked for, its screen has every key (and Ctrl-C still ends)."""
        return action == "interrupt" or not isinstance(self.screen, ConfirmStop)

    # -- drawing --------------------------------------------------------------------

    def redraw(self) -> None:
        """Take a snapshot of the show and show it."""
        if not self.robots.is_attached:  # (a tick while the app ends)
            return
        snap = self.snapshot = self.monitor.snapshot()
        narrow = self._layout()
        _fill(self.robots, ((r.name, robot_cells(r)) for r in snap.robots))
        _fill(self.nodes, ((f"{n.host}/{n.node}", node_cells(n, narrow)) for n in snap.nodes))
        if self.selected is None and snap.robots:
            self.selected = snap.robots[0].name
        robot = next((r for r in snap.robots if r.name == self.selected), None)
        self.joints.border_title = Text(printable(f"joints of {robot.name}" if robot else "joints"))  # (str: markup)
        columns = 2 if robot and narrow and len(robot.joints) > self._joint_rows() else 1
        self.joints.update(joint_lines(robot, self.joints.content_size.width, columns) if robot
                           else Text("no robot on the bus yet", style="italic"))
        lines = max(1, self.events.size.height - 1)
        self.event_lines.update(event_lines(snap.events[-lines:]))
        self.status.update(status_line(snap, self._reach_hint(any(not n.gone for n in snap.nodes))))

    def _layout(self) -> bool:
        """Whether the terminal is narrow (80×24): events below the joints, the nodes'
        columns compact (made again when that changes)."""
        narrow = self.size.width < NARROW
        if narrow != self.narrow:
            self.narrow = narrow
            self.below.set_class(narrow, "narrow")
            self.nodes.clear(columns=True)
            for name in NARROW_NODE_COLUMNS if narrow else NODE_COLUMNS:
                self.nodes.add_column(name, key=name)
        return narrow

    def _joint_rows(self) -> int:
        """Rows the joints may take below the tables, leaving ``EVENTS_MIN`` to the events."""
        taken = sum(w.outer_size.height for w in (self.robots, self.nodes, self.status)) + 1 + 1  # footer, border
        return self.size.height - taken - EVENTS_MIN

    def _reach_hint(self, listed: bool) -> str:
        """With no node on the bus for ``LONELY_S``: whom this session reached and what to check
        (looked up again every ``LONELY_S`` on a thread: it may wait for a link)."""
        now = time.monotonic()
        if listed or self.bus_config is None:
            self._lonely_since, self.reach = now, ""
            return ""
        if now - self._lonely_since >= LONELY_S and (self._reaching is None or not self._reaching.is_alive()):
            self._lonely_since = now
            self._reaching = threading.Thread(target=self._find_reach, args=(self.bus_config,), daemon=True)
            self._reaching.start()
        return self.reach

    def _find_reach(self, cfg: BusConfig) -> None:
        with contextlib.suppress(Exception):  # (the session closing as top ends: nothing to say any more)
            self.reach = reach_hint_now(cfg, self.monitor.bus, "no node on the bus")

    def on_data_table_row_highlighted(self, event: DataTable.RowHighlighted) -> None:
        if event.data_table is self.robots and event.row_key.value is not None:
            self.selected = event.row_key.value
            self.redraw()

    # -- keys -----------------------------------------------------------------------

    def action_next_robot(self, step: int) -> None:
        if self.robots.row_count:
            self.robots.move_cursor(row=(self.robots.cursor_row + step) % self.robots.row_count)

    def action_stop_all(self) -> None:
        robots = [r.name for r in self.snapshot.robots if not r.gone]
        if not robots:
            self.monitor.note("top", "stop", "no robot on the bus to stop")
            return
        self.push_screen(ConfirmStop(robots), lambda yes: self._stop(robots) if yes else self._cancelled())

    def _cancelled(self) -> None:
        self.monitor.note("top", "stop", "cancelled: nothing sent")
        self.redraw()

    def _stop(self, asked: list[str]) -> None:
        """Every robot of the bus at once (``stop_all``: also one that came while the stop was asked)."""
        self.monitor.note("top", "stop", f"sent to every robot ({len(asked)} shown)")
        stop_all(self.monitor.bus, self._replied, self._silent, timeout=STOP_TIMEOUT_S)
        self.redraw()

    def _replied(self, robot: str, outcome: Outcome) -> None:
        """(On a Zenoh thread: the monitor takes it, the next redraw shows it.)"""
        if isinstance(outcome, CommandError):
            self.monitor.note(robot, "stop", f"refused: {outcome.code}: {outcome.message}", alarm=True)
        elif outcome.get("reached") is False:  # (taken, but the robot could not be reached: said, not hidden)
            later = "; sent when it answers again" if outcome.get("pending") else ""
            self.monitor.note(robot, "stop", f"NOT REACHED: {outcome.get('error', '')}{later}", alarm=True)
        else:
            self.monitor.note(robot, "stop", "ok: stopped")

    def _silent(self, robots: list[str], error: CommandError) -> None:
        """(On a Zenoh thread.) The robots on the bus that did not answer the stop, in one line."""
        if robots:
            named = ", ".join(robots[:10]) + (f", … ({len(robots)} in all)" if len(robots) > 10 else "")
            self.monitor.note("top", "stop", f"no answer from {named}: {error.code}: {error.message}", alarm=True)

    def action_quit_top(self) -> None:
        self.exit(int(Exit.OK))

    def action_interrupt(self) -> None:
        self.exit(int(Exit.INTERRUPTED))


def _fill(table: DataTable[Text], rows: Iterable[tuple[str, list[Text]]]) -> None:
    """Add the rows not there yet, update the others in place (the cursor stays put)."""
    columns = list(table.columns)
    for key, shown_cells in rows:
        cells = [Text(printable(c.plain), style=c.style) for c in shown_cells]
        if key not in table.rows:
            table.add_row(*cells, key=key)
            continue
        for column, cell in zip(columns, cells, strict=True):
            shown = table.get_cell(key, column)
            if (shown.plain, str(shown.style)) != (cell.plain, str(cell.style)):  # (Text's == ignores its style)
                table.update_cell(key, column, cell, update_width=True)  # (else a wider value is cropped: 2,15)


def robot_cells(robot: RobotView) -> list[Text]:
    """A robot's row: red once its owner left or while it is not connected, yellow while
    another claim stands by; its state as its owner says it (``bus/connection.py``)."""
    unreached = bool(robot.connection) and not robot.connected
    style = GONE if robot.gone or unreached else WARNING if robot.standby else ""
    state = ("gone" if robot.gone else f"CONFLICT: {', '.join(robot.standby)} stands by" if robot.standby
             else connection.describe(robot.connection) if robot.connection else "on bus")
    if robot.show and not robot.gone:  # (its show: "show closed, opens Tue 10:00")
        state = f"{state}; show {robot.show}"
    latency = f"{robot.latency_ms:.1f} ms" if robot.latency_ms is not None else "-"
    gaps = Text(f"{robot.gaps:,}", style=style or (WARNING if robot.gaps else ""))
    return [Text(robot.name, style=style), Text(robot.owner or "?", style=style), Text(robot.model or "?", style=style),
            Text(f"{robot.rate_hz:.0f}", style=style), Text(latency, style=style), gaps, Text(state, style=style)]


def node_cells(node: NodeView, narrow: bool = False) -> list[Text]:
    """A node's row: red when gone or failed, a loss counter yellow when it moved in the last second
    (``narrow``: host and node in one cell, ``host/node``, as ``NARROW_NODE_COLUMNS``)."""
    style = ALARM if node.gone or node.state == "failed" else ""
    state = f"{node.state}: {node.error}" if node.error else node.state
    rates = ("-", "-") if node.gone else (f"{node.rx_per_s:,.0f}", f"{node.tx_per_s:,.0f}")
    losses = [Text(f"{node.counters.get(k, 0):,}", style=style or (WARNING if k in node.moved else ""))
              for k in ("dropped", "stale", "bad", "errors")]
    where = [Text(f"{node.host}/{node.node}", style=style)] if narrow else [Text(node.host, style=style),
                                                                             Text(node.node, style=style)]
    return [Text(node.adapter, style=style), *where, Text(clock(node.uptime_s), style=style), Text(state, style=style),
            *(Text(r, style=style) for r in rates), *losses]




def clock(seconds: float | None) -> str:
    """``h:mm:ss`` (``-`` when unknown).

    >>> clock(3725.2), clock(None)
    ('1:02:05', '-')
    """
    if seconds is None:
        return "-"
    whole = int(max(0.0, seconds))
    return f"{whole // 3600}:{whole % 3600 // 60:02d}:{whole % 60:02d}"


def joint_lines(robot: RobotView, width: int = 0, columns: int = 1) -> Text:
    """Each joint: its name, its value, its limits, a bar of the value within its limits
    and a sparkline of its last seconds, in ``columns`` columns of ``width`` characters in
    all (0: as wide as they come). What a narrow terminal cannot hold goes first: the
    sparkline shrinks, then the bar, never the name, the value or the limits."""
    joints = robot.joints
    if not joints:
        return Text()
    gap = 2
    each = (width - gap * (columns - 1)) // columns if width else 0
    rows = -(-len(joints) // columns)
    cells = [_joint(j, each, any(x.unit != "rad" for x in joints)) for j in joints]
    text = Text()
    for row in range(rows):
        line = Text()
        for column in range(columns):
            i = column * rows + row
            if i < len(cells):
                if column:
                    line.append(" " * gap)
                line.append_text(cells[i])
        text.append_text(line)
        if row < rows - 1:
            text.append("\n")
    return text


def _joint(joint: JointView, width: int, units: bool) -> Text:
    """One joint's cell, ``width`` characters at most (0: unbounded)."""
    fraction = joint.fraction
    limits = f"{joint.min:+.2f}..{joint.max:+.2f}" if fraction is not None else ""
    unit = ("" if joint.unit == "rad" else printable(joint.unit[:4])) if units else None
    figures = Text.assemble(printable(f"{joint.name:<15}"), f"{joint.value:+6.3f}",
                            f" {unit:<4}" if unit is not None else "", (f" {limits:<12}", "dim"))
    room = width - len(figures) if width else BAR + 2 + 1 + len(joint.history)
    bar_width = BAR if room >= BAR + 2 + 1 + SPARK_MIN else BAR // 2 if room >= BAR // 2 + 2 + 1 + SPARK_MIN else 0
    if bar_width and fraction is not None:
        filled = round(fraction * bar_width)
        figures.append_text(Text.assemble(" [", ("█" * filled, "green"), ("·" * (bar_width - filled), "dim"), "]"))
    elif bar_width:
        figures.append(" " * (bar_width + 3))
    spark = room - (bar_width + 3 if bar_width else 0) - 1
    if spark > 0:
        figures.append(" " + sparkline(joint)[-spark:], style="cyan")
    if width:
        figures.truncate(width)
    return figures


def sparkline(joint: JointView) -> str:
    """The joint's recent values as block characters, spread over their own range but
    at least ``SPARK_SPAN`` of the joint's limits: a gesture fills the height, a wobble
    of a few hundredths of a radian stays near the floor, a still joint is flat.

    >>> sparkline(JointView("LHand", 1.0, 0.0, 1.0, "fraction", (0.0, 0.5, 1.0, 1.0)))
    '▁▅██'
    >>> sparkline(JointView("HeadYaw", 0.3, -2.0, 2.0, "rad", (0.3, 0.3)))
    '▁▁'
    >>> sparkline(JointView("HeadYaw", 0.0, -2.0857, 2.0857, "rad", (0.0, 0.06, 0.0, 0.06)))  # a 3° wobble
    '▁▁▁▁'
    >>> sparkline(JointView("HeadYaw", 0.0, -2.0857, 2.0857, "rad", (0.0, 0.5, 1.0, 0.5)))  # a gesture
    '▁▄█▄'
    """
    values = joint.history
    if not values:
        return ""
    low, high = min(values), max(values)
    floor = SPARK_SPAN * (joint.max - joint.min) if joint.fraction is not None else 0.0
    span = max(high - low, floor) or 1.0
    top = len(SPARKS) - 1
    return "".join(SPARKS[min(top, max(0, round((v - low) / span * top)))] for v in values)


def event_lines(shown: Sequence[EventView]) -> Text:
    """The events, oldest first, one line each (``×N``: N in a row); alarms in red."""
    text = Text()
    for event in shown:
        stamp = time.strftime("%H:%M:%S", time.localtime(event.t))
        times = f" ×{event.repeated}" if event.repeated > 1 else ""
        text.append(printable(f"{stamp} {event.source:<10} {event.kind:<9} {event.text}{times}") + "\n",
                    style=ALARM if event.alarm else "")
    return text


def status_line(snap: Snapshot, hint: str = "") -> Text:
    """How many robots and nodes are on the bus, and what the monitor itself received and refused
    (``hint``: why there is nobody, said after it)."""
    on_bus = sum(not r.gone for r in snap.robots)
    alive = sum(not n.gone for n in snap.nodes)
    counters = snap.counters
    text = Text(f"{on_bus} robot(s), {alive} node(s) on the bus   received {counters.get('received', 0):,}  "
                f"bad {counters.get('bad', 0):,}  dropped {counters.get('dropped', 0):,}")
    if snap.problem:
        text.append(f"   last refused: {printable(snap.problem)}", style=WARNING)
    if hint:
        text.append(f"\n{printable(hint)}", style=WARNING)
    if snap.failure:
        text = Text(f"{printable(snap.failure)}: what is shown no longer changes; quit (q) and start again",
                    style=ALARM)
    return text


# -- the command --------------------------------------------------------------------------


def _arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--every", type=float, default=EVERY_S, metavar="SECONDS", help="redraw this often")


def _top(args: argparse.Namespace, env: Environment) -> Exit:
    if not 0.02 <= args.every <= 10:
        raise ConfigError(f"--every {args.every:g}: give a redraw interval of 0.02 to 10 s, e.g. --every 0.25")
    if not (_is_terminal(sys.__stdin__) and _is_terminal(sys.__stderr__)):
        raise SonibusError("top draws on a terminal, and its input or its error output is not one (a pipe, a "
                           "file): run it in a terminal, or use `sonibus nodes` / `sonibus echo KEYEXPR` instead")
    cfg = bus_config(args)
    handlers = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM)}
    with joined(cfg, control=True) as bus, Monitor(bus) as monitor:
        app = TopApp(monitor, args.every, signals=True, bus_config=cfg)
        try:
            status = app.run()
        finally:  # (the app's loop handled them; closing it left Python's defaults)
            for sig, handler in handlers.items():
                signal.signal(sig, handler)
    return Exit(status) if status is not None else Exit.ERROR


def _is_terminal(stream: Any) -> bool:
    return stream is not None and stream.isatty()


TOP = Command("top", "a live view of robots, nodes, joints and events (keys: s stop all, q quit)",
              _arguments, _top, bus=True)

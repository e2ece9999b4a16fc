"""Where a live stream's solved frames go: OSC (python-osc) and WebSocket (websockets) clients and servers in
the usual roles; each output is a callable ``send(frame, time_s, joints (21, 3), phi (27,))``.

- :class:`OscOutput` sends one OSC message per frame to ``HOST:PORT``: address ``/handcap/joints`` with the
  frame number, the time (s) and the 63 joint coordinates in metres (wrist first, then as
  :data:`handcap.hand.anatomy.JOINT_NAMES` and the tips), then ``/handcap/angles`` with the 27 angles (rad).
- :class:`WebSocketOutput` serves ``ws://HOST:PORT``: every connected client gets one JSON text message per
  frame, ``{"frame", "time", "joints": [[x, y, z] x 21], "angles": [27]}``.
- :class:`LslOutput` opens two Lab Streaming Layer outlets (pylsl), ``NAME-joints`` (type ``MoCap``, 63
  float32 channels ``wrist_x`` ... in metres) and ``NAME-angles`` (27 channels in radians), each at the
  stream's nominal rate with a unique source id; every frame is one sample of each, stamped with LSL's clock.
"""

from __future__ import annotations

import asyncio
import json
import os
import threading
import uuid
from pathlib import Path

import numpy as np

from handcap.core.errors import HandcapError


def _endpoint(text: str, default_host: str = "127.0.0.1") -> tuple[str, int]:
    host, _, port = str(text).rpartition(":")
    try:
        number = int(port)
    except ValueError:
        raise HandcapError(f"{text!r}: give PORT or HOST:PORT") from None
    if not 0 < number < 65536:
        raise HandcapError(f"{text!r}: the port must be 1-65535")
    return host or default_host, number


class OscOutput:
    """Send each frame as OSC messages over UDP.

    Parameters
    ----------
    target : str
        ``HOST:PORT`` (or ``PORT`` for this machine).
    """

    def __init__(self, target: str):
        try:
            from pythonosc.osc_message_builder import OscMessageBuilder  # noqa: PLC0415 (optional extra 'stream')
            from pythonosc.udp_client import SimpleUDPClient  # noqa: PLC0415
        except ImportError:
            raise HandcapError("OSC output needs python-osc: pip install 'handcap[stream]'") from None
        self.host, self.port = _endpoint(target)
        self.client, self.builder = SimpleUDPClient(self.host, self.port), OscMessageBuilder

    def __call__(self, frame: int, time_s: float, joints, phi) -> None:
        """Send one frame (see the module docstring)."""
        for address, head, values in (("/handcap/joints", (int(frame), float(time_s)), joints),
                                      ("/handcap/angles", (int(frame),), phi)):
            message = self.builder(address)
            message.add_arg(head[0], "i")
            for value in head[1:]:
                message.add_arg(value, "f")
            for value in np.nan_to_num(np.asarray(values, dtype=np.float64)).ravel().tolist():
                message.add_arg(value, "f")  # typed: python-osc need not guess 63 times
            self.client.send(message.build())

    def close(self) -> None:
        """Nothing to release (UDP)."""


class LslOutput:
    """Push each frame as one sample of two LSL outlets (see the module docstring).

    Parameters
    ----------
    name : str
        Stream name prefix (``NAME-joints``, ``NAME-angles``).
    rate : float
        Nominal frames per second.
    joint_names, angle_names : sequence of str
        The 21 joints' and 27 angles' names, for the channel labels.
    """

    def __init__(self, name: str, rate: float, joint_names, angle_names):
        # liblsl reads its settings when loaded: lsl_api.cfg asks for only errors in its log (it prints its version
        # and configuration otherwise; the file takes no comments), unless the user names a settings file
        os.environ.setdefault("LSLAPICFG", str(Path(__file__).with_name("lsl_api.cfg")))
        try:
            import pylsl  # noqa: PLC0415 (optional extra 'stream')
        except (ImportError, RuntimeError):
            raise HandcapError("LSL output needs pylsl: pip install 'handcap[stream]'") from None
        self.outlets = []
        for kind, channels in (("joints", [f"{j}_{a}" for j in joint_names for a in "xyz"]),
                               ("angles", list(angle_names))):
            info = pylsl.StreamInfo(f"{name}-{kind}", "MoCap", len(channels), float(rate), "float32",
                                    f"handcap-{name}-{kind}-{uuid.uuid4().hex[:8]}")
            labels = info.desc().append_child("channels")
            for label in channels:
                channel = labels.append_child("channel")
                channel.append_child_value("label", label)
                channel.append_child_value("unit", "metres" if kind == "joints" else "radians")
            self.outlets.append(pylsl.StreamOutlet(info))
        self.source_ids = tuple(o.get_info().source_id() for o in self.outlets)

    def __call__(self, frame: int, time_s: float, joints, phi) -> None:
        """Push one frame (see the module docstring)."""
        self.outlets[0].push_sample(np.asarray(joints, dtype=np.float32).ravel())
        self.outlets[1].push_sample(np.asarray(phi, dtype=np.float32))

    def close(self) -> None:
        """Close the outlets."""
        self.outlets.clear()


class WebSocketOutput:
    """Serve each frame as JSON to every connected WebSocket client (a server on its own thread).

    Parameters
    ----------
    listen : str
        ``PORT`` or ``HOST:PORT`` to listen on (port 0: any free port, see :attr:`port`).
    """

    def __init__(self, listen: str):
        try:
            from websockets.asyncio.server import broadcast, serve  # noqa: PLC0415 (optional extra 'stream')
        except ImportError:
            raise HandcapError("WebSocket output needs websockets: pip install 'handcap[stream]'") from None
        host, port = _endpoint(listen) if str(listen) != "0" else ("127.0.0.1", 0)
        self.clients, self.broadcast = set(), broadcast
        self.loop = asyncio.new_event_loop()
        ready = threading.Event()

        async def handler(connection):
            self.clients.add(connection)
            try:
                await connection.wait_closed()
            finally:
                self.clients.discard(connection)

        async def main():
            self.server = await serve(handler, host, port)
            self.port = self.server.sockets[0].getsockname()[1]
            ready.set()
            await self.server.serve_forever()

        self.thread = threading.Thread(target=lambda: self._run(main()), daemon=True)
        self.thread.start()
        if not ready.wait(10):
            raise HandcapError(f"could not listen for WebSocket clients on {host}:{port}")

    def _run(self, coroutine) -> None:
        asyncio.set_event_loop(self.loop)
        try:
            self.loop.run_until_complete(coroutine)
        except asyncio.CancelledError:
            pass

    def __call__(self, frame: int, time_s: float, joints, phi) -> None:
        """Send one frame to every client (see the module docstring)."""
        if not self.clients:
            return
        text = json.dumps({"frame": int(frame), "time": float(time_s),
                           "joints": np.round(np.nan_to_num(joints), 6).tolist(),
                           "angles": np.round(np.nan_to_num(phi), 6).tolist()})
        # websockets' broadcast writes to every client without waiting on any (a slow one drops behind alone),
        # one call on the server's loop per frame.
        self.loop.call_soon_threadsafe(self.broadcast, self.clients, text)

    def close(self) -> None:
        """Stop the server."""
        self.loop.call_soon_threadsafe(self.server.close)
        self.thread.join(5)

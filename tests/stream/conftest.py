"""A fake Qualisys Track Manager real-time server for loopback tests, built on qtm-rt's own protocol
definitions: its packet headers and component structs make the packets, its Receiver parses the commands.

It answers ``version``, ``getparameters`` (General/Frequency and the 3D labels) and ``streamframes ... 3d`` or
``3dnolabels``, sending a take's frames (millimetres, NaN where a labelled marker is not seen) at its rate, then
closes the connection.
"""

from __future__ import annotations

import asyncio
import threading

import numpy as np
import pytest

try:
    from qtm_rt.packet import (RT3DComponent, RT3DMarkerPosition, RT3DMarkerPositionNoLabel, RTComponentData,
                               RTDataQRTPacket, RTheader, QRTComponentType, QRTPacketType)
    from qtm_rt.receiver import Receiver
except ImportError:  # the fixture skips, saying why
    Receiver = None


def _packet(kind: QRTPacketType, body: bytes) -> bytes:
    return RTheader.pack(RTheader.size + len(body), kind.value) + body


class FakeQtm:
    """Serve ``positions`` (T, K, 3) metres with ``names`` at ``rate`` on 127.0.0.1 (``port``), numbered ``numbers``
    (T,) (default 0 to T - 1)."""

    def __init__(self, positions, names, rate: float, numbers=None):
        self.positions, self.names, self.rate = np.asarray(positions), list(names), float(rate)
        # each frame's number as QTM sends it (default 0, 1, 2, ...): skipped numbers are frames QTM fell behind on
        self.numbers = np.arange(len(self.positions)) if numbers is None else np.asarray(numbers)
        self.commands = []
        self.loop = asyncio.new_event_loop()
        ready = threading.Event()

        async def main():
            self.server = await asyncio.start_server(self._client, "127.0.0.1", 0)
            self.port = self.server.sockets[0].getsockname()[1]
            ready.set()

        self.thread = threading.Thread(target=self.loop.run_forever, daemon=True)
        self.thread.start()
        asyncio.run_coroutine_threadsafe(main(), self.loop)
        ready.wait(10)

    def _xml(self) -> bytes:
        labels = "".join(f"<Label><Name>{n}</Name><RGBColor>255</RGBColor></Label>" for n in self.names)
        return (f"<QTM_Parameters_Ver_1.25><General><Frequency>{self.rate:g}</Frequency></General><The_3D>"
                f"<AxisUpwards>+Z</AxisUpwards>{labels}</The_3D></QTM_Parameters_Ver_1.25>").encode() + b"\0"

    def _frame(self, t: int, labelled: bool) -> bytes:
        mm = self.positions[t] * 1000.0
        if labelled:
            kind, body = QRTComponentType.Component3d, b"".join(RT3DMarkerPosition.format.pack(*p) for p in mm)
            count = len(mm)
        else:
            seen = mm[np.isfinite(mm).all(axis=1)]
            kind = QRTComponentType.Component3dNoLabels
            body = b"".join(RT3DMarkerPositionNoLabel.format.pack(*p, k) for k, p in enumerate(seen))
            count = len(seen)
        component = RT3DComponent.format.pack(count, 0, 0) + body
        number = int(self.numbers[t])
        data = (RTDataQRTPacket.pack(int(number * 1e6 / self.rate), number, 1)
                + RTComponentData.pack(RTComponentData.size + len(component), kind.value) + component)
        return _packet(QRTPacketType.PacketData, data)

    async def _client(self, reader, writer):
        commands = []
        receiver = Receiver({QRTPacketType.PacketCommand: commands.append})
        writer.write(_packet(QRTPacketType.PacketCommand, b"QTM RT Interface connected\0"))
        while not reader.at_eof():
            data = await reader.read(4096)
            if not data:
                break
            receiver.data_received(data)
            while commands:
                text = commands.pop(0).decode().lower()
                self.commands.append(text)
                if text.startswith("version"):
                    writer.write(_packet(QRTPacketType.PacketCommand, f"Version set to {text.split()[1]}\0".encode()))
                elif text.startswith("getparameters"):
                    writer.write(_packet(QRTPacketType.PacketXML, self._xml()))
                elif text.startswith("streamframes") and "stop" not in text:
                    labelled = text.split()[-1] == "3d"
                    for t in range(len(self.positions)):
                        writer.write(self._frame(t, labelled))
                        await writer.drain()
                        await asyncio.sleep(1.0 / self.rate)
                    writer.close()
                    return
            await writer.drain()

    def close(self) -> None:
        self.loop.call_soon_threadsafe(self.server.close)
        self.loop.call_soon_threadsafe(self.loop.stop)
        self.thread.join(5)


@pytest.fixture
def fake_qtm():
    """Start :class:`FakeQtm` servers (``fake_qtm(positions, names, rate)``); all closed after the test."""
    if Receiver is None:
        pytest.skip("the fake QTM server needs qtm-rt (the extra 'stream')")
    servers = []

    def start(positions, names, rate, numbers=None):
        servers.append(FakeQtm(positions, names, rate, numbers))
        return servers[-1]

    yield start
    for server in servers:
        server.close()

"""Links: sockets, MAVLink framing and signing, the receive path and routing between links."""
from __future__ import annotations

import selectors
import socket
import time
from typing import TYPE_CHECKING, Any, Optional, Tuple

from .recording import jsonable
from .vocabulary import mavlink

if TYPE_CHECKING:
    from .autopilot import StandinAutopilot


def signing_timestamp() -> int:
    # MAVLink 2 signing timestamps count 10 us units since 2015-01-01 (mavlink.io/en/guide/message_signing.html).
    return int((time.time() - 1420070400) * 100000)


def accept_unsigned(_mav: Any, msg_id: int) -> bool:
    # With signing on, ArduPilot accepts only RADIO_STATUS unsigned (GCS_Signing.cpp accept_unsigned_callback:
    # "we accept RADIO_STATUS messages unsigned as the radio doesn't know the key").
    return msg_id == mavlink.MAVLINK_MSG_ID_RADIO_STATUS


def parse_url(url: str) -> Tuple[str, str, int]:
    parts = url.split(":")
    if len(parts) != 3 or parts[0] not in ("tcp", "udp", "udpout"):
        raise ValueError(f"listen URL must be tcp:HOST:PORT, udp:HOST:PORT or udpout:HOST:PORT, got {url!r}")
    host = parts[1]
    if host not in ("127.0.0.1", "localhost") and not host.startswith("127."):
        raise ValueError("the stand-in listens on loopback only")
    return parts[0], "127.0.0.1" if host == "localhost" else host, int(parts[2])


def is_signed_frame(buf: bytes) -> bool:
    return len(buf) > 2 and buf[0] == 0xFD and bool(buf[2] & 0x01)


def frame_msgid(buf: bytes) -> Optional[int]:
    if len(buf) >= 10 and buf[0] == 0xFD:
        return buf[7] | (buf[8] << 8) | (buf[9] << 16)
    if len(buf) >= 6 and buf[0] == 0xFE:
        return buf[5]
    return None


class _Writer:
    """File-like sink pymavlink's MAVLink.send() writes into."""

    def __init__(self, link: "Link") -> None:
        self.link = link

    def write(self, buf: bytes) -> None:
        self.link.send_raw(bytes(buf))


class Link:
    """One peer: a TCP client connection or a UDP peer. Own parser, own sequence numbers (ArduPilot keeps
    per-channel state), own signing streams."""

    def __init__(self, owner: "StandinAutopilot", ident: int, sock: socket.socket, addr: Any, udp: bool) -> None:
        self.owner = owner
        self.ident = ident
        self.sock = sock
        self.addr = addr
        self.udp = udp
        self.mav = mavlink.MAVLink(_Writer(self), owner.cfg.sysid, owner.cfg.compid)
        self.mav.robust_parsing = True
        key = owner.cfg.signing_key
        if key is not None:
            self.mav.signing.secret_key = key
            self.mav.signing.sign_outgoing = True
            self.mav.signing.link_id = ident & 0xFF
            self.mav.signing.timestamp = signing_timestamp()
            self.mav.signing.allow_unsigned_callback = accept_unsigned
        self.seen: set = set()          # (sysid, compid) heard on this link, for routing
        self.closed = False
        self.bytes_in = 0
        self.bytes_out = 0
        # The raw byte streams, when cfg.capture_wire: lets a test compare a peer's .tlog with the wire.
        self.wire_out: Optional[bytearray] = bytearray() if owner.cfg.capture_wire else None
        self.wire_in: Optional[bytearray] = bytearray() if owner.cfg.capture_wire else None
        if owner.cfg.capture_wire:
            owner.wire_links.append(self)

    def send_raw(self, buf: bytes) -> None:
        if self.closed or self.owner.in_outage():
            return
        try:
            if self.udp:
                if self.addr is not None:
                    self.sock.sendto(buf, self.addr)
            else:
                self.sock.sendall(buf)
            self.bytes_out += len(buf)
            if self.wire_out is not None:
                self.wire_out += buf
        except OSError:
            self.closed = True

    def send(self, msg: Any) -> None:
        self.mav.send(msg)


class LinkIO:
    """The socket side of StandinAutopilot (mixed into it): accepting and reading links, decoding frames,
    counting what is malformed, routing between links and dispatching to the ``_h_<TYPE>`` handlers."""

    def _new_ident(self) -> int:
        i = self._next_link
        self._next_link += 1
        return i

    def _accept(self) -> None:
        assert self._server is not None
        try:
            conn, addr = self._server.accept()
        except OSError:
            return
        conn.setblocking(True)
        conn.settimeout(2.0)
        conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        link = Link(self, self._new_ident(), conn, addr, udp=False)
        with self.lock:
            self.links.append(link)
            self.rec.add(self.wall(), self._sim, "connect", link=link.ident, addr=str(addr))
        self._sel.register(conn, selectors.EVENT_READ, link)

    def _read(self, link: Link) -> None:
        try:
            if link.udp:
                data, addr = link.sock.recvfrom(65536)
                link.addr = addr
            else:
                data = link.sock.recv(65536)
        except (BlockingIOError, socket.timeout):
            return
        except OSError:
            data = b""
        if not data:
            if not link.udp:
                with self.lock:
                    link.closed = True
                    self.rec.add(self.wall(), self._sim, "disconnect", link=link.ident)
                try:
                    self._sel.unregister(link.sock)
                    link.sock.close()
                except (OSError, KeyError, ValueError):
                    pass
            return
        link.bytes_in += len(data)
        if link.wire_in is not None:
            link.wire_in += data
        msgs = link.mav.parse_buffer(data) or []
        with self.lock:
            for m in msgs:
                self._on_message(link, m)

    # ----- receive path ---------------------------------------------------------------------------

    def _on_message(self, link: Link, m: Any) -> None:
        t = m.get_type()
        if t == "BAD_DATA":
            reason = getattr(m, "reason", "")
            if "signature" in reason:
                # pymavlink raises "Invalid signature" for unsigned or badly signed frames when a key is set
                if is_signed_frame(m.data):
                    self.counters["rx_bad_signature"] += 1
                else:
                    self.counters["rx_unsigned_rejected"] += 1
                self.rec.add(self.wall(), self._sim, "rejected", link=link.ident, reason=reason,
                             signed=is_signed_frame(m.data), msgid=frame_msgid(m.data))
            elif reason.startswith("Bad prefix"):
                self.counters["rx_garbage_bytes"] += len(m.data)
            else:
                self.counters["rx_bad_frames"] += 1
                self.counters["rx_garbage_bytes"] += len(m.data)
            return
        if t == "UNKNOWN" or t.startswith("UNKNOWN"):
            self.counters["rx_bad_frames"] += 1
            return
        hdr = m.get_header()
        src = (hdr.srcSystem, hdr.srcComponent)
        dropped = self.in_outage()
        data = {k: jsonable(v) for k, v in m.to_dict().items() if k != "mavpackettype"}
        self.rec.add(self.wall(), self._sim, "received", link=link.ident, type=t, src=list(src),
                     signed=bool(getattr(m, "_signed", False)), dropped=dropped, fields=data)
        if dropped:
            self.counters["rx_dropped_in_outage"] += 1
            return
        self.counters["rx_messages"] += 1
        link.seen.add(src)
        # routing (libraries/GCS_MAVLink/MAVLink_routing.cpp): broadcasts go to every other link;
        # messages for another component go where that component was heard.
        tsys = getattr(m, "target_system", 0)
        tcomp = getattr(m, "target_component", 0)
        self._route(link, m, tsys, tcomp)
        if tsys not in (0, self.cfg.sysid) or tcomp not in (0, self.cfg.compid):
            return
        handler = getattr(self, "_h_" + t, None)
        if handler is not None:
            try:
                handler(link, m)
            except Exception as e:  # a fixture bug must show up in the recording, not kill the link thread
                self.counters["handler_errors"] = self.counters.get("handler_errors", 0) + 1
                self.rec.add(self.wall(), self._sim, "handler_error", type=t, error=repr(e))

    def _route(self, src_link: Link, m: Any, tsys: int, tcomp: int) -> None:
        if len(self.links) < 2:
            return
        buf = bytes(m.get_msgbuf())
        for link in self.links:
            if link is src_link:
                continue
            broadcast = tsys == 0
            for_link = any(s == tsys and (tcomp == 0 or c == tcomp) for s, c in link.seen)
            if broadcast or (for_link and (tsys, tcomp) != (self.cfg.sysid, self.cfg.compid)):
                link.send_raw(buf)
                self.counters["forwarded"] += 1

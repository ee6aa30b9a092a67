"""pyScienceMode's side of the ScienceMode 2 peer test (tests/tests/it/sciencemode_peer.rs).

Only pyScienceMode's own code builds and parses packets here; this script just calls it and
prints what it found as JSON lines, for the Rust test to compare with its own codec.

    sciencemode_peer.py parse     stdin: hex of device packets (our encoder's output).
                                  Splits them with pyScienceMode's serial reader
                                  (RehastimGeneric._read_packet) and reads each with its ack
                                  parsers; also rebuilds each packet from the fields it read
                                  with its packet builder (utils.packet_construction).
    sciencemode_peer.py rebuild   stdin: JSON lines {number, command, data}; prints the
                                  bytes pyScienceMode's packet builder makes of them.
    sciencemode_peer.py client    prints the packets pyScienceMode's Rehastim2 client builds
                                  for a fixed session (InitAck, InitChannelListMode,
                                  StartChannelListMode, pause, Watchdog, StopChannelListMode).
"""

import json
import sys

from pysciencemode import Channel, Device, Modes
from pysciencemode.acks import (
    get_mode_ack,
    init_stimulation_ack,
    rehastim_error,
    start_stimulation_ack,
    stop_stimulation_ack,
)
from pysciencemode.enums import Rehastim2Commands
from pysciencemode.rehastim2_interface import Rehastim2
from pysciencemode.sciencemode import RehastimGeneric
from pysciencemode.utils import calc_electrode_number, packet_construction, signed_int


class FakePort:
    """The part of pyserial's Serial that RehastimGeneric._read_packet uses."""

    def __init__(self, data: bytes):
        self.data = data

    def inWaiting(self):
        return len(self.data)

    def read(self, n):
        chunk, self.data = self.data[:n], self.data[n:]
        return chunk


def ack_text(packet: bytes):
    """What pyScienceMode's own ack parsers make of a device packet (None: no parser)."""
    cmd = packet[6]
    c = Rehastim2Commands
    if cmd == c.GetStimulationModeAck.value:
        return get_mode_ack(packet)
    if cmd == c.InitChannelListModeAck.value:
        return init_stimulation_ack(packet)
    if cmd == c.StartChannelListModeAck.value:
        return start_stimulation_ack(packet)
    if cmd == c.StopChannelListModeAck.value:
        return stop_stimulation_ack(packet)
    if cmd == c.StimulationError.value:
        return rehastim_error(signed_int(packet[7:8]))
    return None


def parse(stream: bytes):
    reader = object.__new__(RehastimGeneric)
    reader.port = FakePort(stream)
    for packet in reader._read_packet():
        name = Rehastim2Commands(packet[6]).name
        data = list(packet[7:-1])
        rebuilt = packet_construction(packet[5], name, data if data else None)
        print(
            json.dumps(
                {
                    "number": packet[5],
                    "command": name,
                    "data": data,
                    "ack": ack_text(packet),
                    "bytes": packet.hex(),
                    "rebuilt": rebuilt.hex(),
                }
            )
        )


def rebuild(lines):
    for line in lines:
        if not line.strip():
            continue
        p = json.loads(line)
        data = p["data"] if p["data"] else None
        print(packet_construction(p["number"], p["command"], data).hex())


def client():
    # A Rehastim2 without its serial port: its packet builders only read these fields.
    stim = object.__new__(Rehastim2)
    stim.packet_count = 7
    emit = lambda what, packet: print(json.dumps({"what": what, "bytes": packet.hex()}))
    emit("init_ack", stim._init_ack(3))
    channels = [
        Channel(Modes.SINGLE, 1, 20, 200, device_type=Device.Rehastim2),
        Channel(Modes.DOUBLET, 3, 32, 300, enable_low_frequency=True, device_type=Device.Rehastim2),
    ]
    # What Rehastim2.init_channel sets before building its packet.
    stim.stimulation_interval = 25
    stim.inter_pulse_interval = 3
    stim.low_frequency_factor = 2
    stim.electrode_number = calc_electrode_number(channels)
    stim.electrode_number_low_frequency = calc_electrode_number(channels, enable_low_frequency=True)
    stim.set_stimulation_signal(channels)
    emit("init_channel_list", stim._packet_init_stimulation())
    stim.packet_count = 8
    emit("start_channel_list", stim._packet_start_stimulation())
    # Rehastim2.pause_stimulation: the same list with every amplitude 0.
    stim.packet_count = 9
    stim.amplitude = [0] * len(channels)
    emit("pause", stim._packet_start_stimulation())
    stim.packet_count = 11
    emit("watchdog", stim._packet_watchdog())
    stim.packet_count = 12
    emit("stop", packet_construction(stim.packet_count, "StopChannelListMode"))


if __name__ == "__main__":
    mode = sys.argv[1]
    if mode == "parse":
        parse(bytes.fromhex(sys.stdin.read().strip()))
    elif mode == "rebuild":
        rebuild(sys.stdin.read().splitlines())
    elif mode == "client":
        client()
    else:
        raise SystemExit(f"unknown mode {mode}")

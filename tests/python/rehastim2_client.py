"""pyScienceMode's Rehastim2 client driving a (virtual) RehaStim 2 through a serial port.

    rehastim2_client.py PORT session
    rehastim2_client.py PORT killed

Connects (Init / InitAck), initialises channel list mode on channels 1 (single, 200 us,
20 mA) and 2 (doublet, 100 us, 10 mA) at a 50 ms main interval, stimulates for 0.5 s and
pauses (pyScienceMode's pause: the same list at 0 mA), updates channel 1 to 30 mA for
0.3 s, stops, then sends three single pulses (channel 1, 250 us, 40 mA) with
pyScienceMode's own packet builder and send path (its client has no single-pulse method),
and disconnects. Prints one JSON line per step with the answer pyScienceMode read.

`killed`: connects, starts the same channel list and kills itself (SIGKILL) while the
device stimulates, as a host process that dies does: from then on the device hears nothing.
Used by tests/tests/it/rehastim2_pty.rs; only pyScienceMode talks to the port.
"""

import json
import os
import signal
import sys
import time

from pysciencemode import Channel, Device, Modes, Rehastim2
from pysciencemode.utils import packet_construction


def step(what, ack):
    print(json.dumps({"what": what, "ack": ack.hex() if isinstance(ack, bytes) else ack}), flush=True)


def main(port):
    stim = Rehastim2(port, show_log=False)
    step("connected", "InitAck")
    ch1 = Channel(Modes.SINGLE, 1, 20, 200, device_type=Device.Rehastim2)
    ch2 = Channel(Modes.DOUBLET, 2, 10, 100, device_type=Device.Rehastim2)
    stim.init_channel(stimulation_interval=50, list_channels=[ch1, ch2])
    step("init_channel", None)
    stim.start_stimulation(stimulation_duration=0.5)
    step("start_then_pause", None)
    ch1.set_amplitude(30)
    stim.start_stimulation(upd_list_channels=[ch1, ch2])
    step("update", None)
    time.sleep(0.3)
    stim.end_stimulation()
    step("stop", None)
    for _ in range(3):
        stim.send_generic_packet(
            "SinglePulse", packet_construction(stim.packet_count, "SinglePulse", [0, 0, 250, 40])
        )
        step("single_pulse", stim._get_last_ack())
        time.sleep(0.05)
    stim.disconnect()
    stim.close_port()
    step("disconnected", None)


def killed(port):
    stim = Rehastim2(port, show_log=False)
    ch1 = Channel(Modes.SINGLE, 1, 20, 200, device_type=Device.Rehastim2)
    ch2 = Channel(Modes.DOUBLET, 2, 10, 100, device_type=Device.Rehastim2)
    stim.init_channel(stimulation_interval=50, list_channels=[ch1, ch2])
    stim.start_stimulation()
    time.sleep(0.3)
    step("started", None)
    os.kill(os.getpid(), signal.SIGKILL)


if __name__ == "__main__":
    {"session": main, "killed": killed}[sys.argv[2]](sys.argv[1])

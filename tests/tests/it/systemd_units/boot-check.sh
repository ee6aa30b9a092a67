#!/bin/sh
# The boot test's check, run as a oneshot unit by a real systemd (PID 1 of a User-Mode Linux
# guest; see tests/tests/it/systemd_units/boot.rs). It installs the bench package
# (fes-stack-bench, $FES_DEB) with dpkg as an operator would, starts fes.target, and exercises ordering, the watchdog, BindsTo and the
# driver's ExecStopPost safe stop. Every result is a line "@@SD <key> <value...>" on the
# console; the host asserts on them. Always ends by powering the guest off.
exec > /dev/console 2>&1
R="@@SD"
say() { echo "$R $*"; }
finish() { say done; systemctl --no-block poweroff; exit 0; }
prop() { systemctl show -p "$2" --value "$1.service"; }
now() { cut -d' ' -f1 /proc/uptime | cut -d. -f1; }
wait_for() { # unit property value timeout_s
  end=$(($(now) + $4))
  while [ "$(prop "$1" "$2")" != "$3" ]; do
    [ "$(now)" -ge "$end" ] && return 1; sleep 1; done; return 0; }
units="fes-can.service fes-sim-muscle.service fes-stim-driver.service fes-rt-core.service fes-supervisor.service"
# One systemctl call per snapshot (every exec is slow in the guest): "@@SD <tag> <unit>
# Id=... ActiveState=... ..." per unit.
state() {
  systemctl show -p Id -p ActiveState -p SubState -p MainPID -p NRestarts -p Result \
    -p ActiveEnterTimestampMonotonic -p ExecMainStartTimestampMonotonic $units |
    awk -v tag="$1" -v r="$R" 'BEGIN { line = "" }
      /^$/ { if (line != "") print r, tag, line; line = ""; next }
      { line = line " " $0 }
      END { if (line != "") print r, tag, line }'
}
# The stack's journal for the host's failure message: every unit of ours, and systemd's
# own lines about them (start limits, watchdog, dependency jobs).
dump_journal() {
  say journal-begin
  journalctl -b --no-pager -o short-monotonic -u 'fes-*' | tail -n 150
  journalctl -b --no-pager -o short-monotonic _PID=1 | grep -i 'fes' | tail -n 60
  say journal-end
}
if [ -n "$FES_BOOT_DEBUG" ]; then
  chrt -f 99 sh -c 'while sleep 5; do echo "== ps"; ps -eLo pid,tid,cls,rtprio,pcpu,stat,comm --sort=-pcpu | head -12; done' &
fi
cd "$FES_REPO" || { say fail "no repository at $FES_REPO"; finish; }
# The package: postinst makes the user and runtime paths, reloads systemd (which runs the
# package's placement generator: one CPU here, so CPU 0 for everything) and enables
# fes.target without starting it.
dpkg -i "$FES_DEB" > /run/install.log 2>&1
say install $? "$(tail -n 1 /run/install.log)"
sed 's/^/install-log: /' /run/install.log
say enabled "$(systemctl is-enabled fes.target)"
say active-after-install "$(systemctl is-active fes.target)"
say rt-core-dropins "$(systemctl show -p DropInPaths --value fes-rt-core.service)"
say rt-core-cpus "$(systemctl show -p CPUAffinity --value fes-rt-core.service)"
# The guest's one emulated CPU, shared with rt-core's and the driver's SCHED_FIFO 1 kHz
# loops, starves every normal-priority thread for seconds at a time: the supervisor missed
# READY within the rig's TimeoutStartSec=15 (three times, then StartLimitBurst), and its
# WatchdogSec=5 (2026-12-02: "fes-supervisor.service: Watchdog timeout" 15 s after rt-core's
# watchdog restart), the driver's notifier missed its WatchdogSec=2 once while rt-core
# restarted, and each such restart cascades (BindsTo) into the start limits. Test-only
# drop-ins give the units the time, and lift the start limits. rt-core's included: its
# WATCHDOG=1 comes from a normal-priority thread, and in 3 of 6 boots on 2026-12-02 that
# thread was starved past the rig's WatchdogSec=2 while the stack started ("fes-rt-core.service:
# Watchdog timeout (limit 2s)" with the loop running), so rt-core was restarting when the
# check looked. Here it gets 10 s; the SIGSTOP step below still proves the mechanism (a
# stalled rt-core is killed and restarted), and the rig's 2 s is checked on the unit file
# (systemd_units::safety_iceoryx2_and_hardening_settings). The rig's units are unchanged.
slow_guest() { # unit, [Service] lines
  mkdir -p "/etc/systemd/system/$1.d"
  printf '[Unit]\nStartLimitIntervalSec=0\n[Service]\n%s\n' "$2" \
    > "/etc/systemd/system/$1.d/uml-slow-guest.conf"
}
slow_guest fes-supervisor.service 'TimeoutStartSec=150
WatchdogSec=60'
slow_guest fes-stim-driver.service 'TimeoutStartSec=60
WatchdogSec=30'
slow_guest fes-sim-muscle.service 'TimeoutStartSec=60'
slow_guest fes-rt-core.service 'TimeoutStartSec=60
WatchdogSec=10'
systemctl daemon-reload
systemctl start fes.target
say start $?
state started
wait_for fes-rt-core ActiveState active 60 || say fail "rt-core not active within 60 s"
wait_for fes-supervisor ActiveState active 180 || say fail "supervisor not active within 180 s"
# Every unit up at once (a unit restarting would make the snapshot's order meaningless).
for u in fes-can fes-sim-muscle fes-stim-driver fes-rt-core fes-supervisor; do
  wait_for "$u" ActiveState active 60 || say fail "$u not active within 60 s"
done
say supervisor-restarts "$(prop fes-supervisor NRestarts)"
state up

# Whose publishers: the rig's driver configuration names the units rt-core and the
# supervisor must run in (watchdog.generator_unit, supervisor_unit); under systemd the
# driver finds each publisher's process in its unit's cgroup and logs it alive, never
# FOREIGN. journald writes late in the guest: wait up to 60 s for both lines.
driver_log() { journalctl -b --no-pager -u fes-stim-driver.service; }
end=$(($(now) + 60))
until { driver_log | grep -q 'supervisor (DriverCommand publisher) alive' &&
        driver_log | grep -q 'StimTick publisher alive'; } || [ "$(now)" -ge "$end" ]; do sleep 1; done
say supervisor-cgroup "$(sed -n 's/^0:://p' "/proc/$(prop fes-supervisor MainPID)/cgroup")"
say driver-sees-supervisor "$(driver_log | grep -c 'supervisor (DriverCommand publisher) alive')"
say driver-sees-generator "$(driver_log | grep -c 'StimTick publisher alive')"
say driver-foreign "$(driver_log | grep -c 'FOREIGN')"

# The private bus: the CAN interface exists only in /run/netns/fes, which the driver and
# the virtual stimulator joined (rt-core did not); the host's namespace has no such link.
iface=$(sed -n 's/^FES_CAN_IFACE=//p' /etc/fes/can.env)
if ip link show "$iface" >/dev/null 2>&1; then say netns-host-iface visible; else say netns-host-iface absent; fi
if ip -n fes link show "$iface" >/dev/null 2>&1; then say netns-fes-iface present; else say netns-fes-iface missing; fi
ns_of() { readlink "/proc/$(prop "$1" MainPID)/ns/net"; }
say netns-ids "$(ns_of fes-stim-driver) $(ns_of fes-sim-muscle) $(ns_of fes-rt-core) $(stat -L -c 'net:[%i]' /run/netns/fes) $(readlink /proc/1/ns/net)"

# Watchdog: stop rt-core's process; systemd must kill it (WatchdogSec, 10 s here) and
# restart it: its restart count must grow past the count before the stop.
restarts0=$(prop fes-rt-core NRestarts)
say rt-core-restarts-before "$restarts0"
pid=$(prop fes-rt-core MainPID)
# MainPID 0 (rt-core not running): `kill 0` would signal this script's own process group.
[ "${pid:-0}" -gt 0 ] && kill -STOP "$pid" || say fail "rt-core not running before the watchdog check"
say stopped-rt-core "$pid"
end=$(($(now) + 45)); while [ "$(prop fes-rt-core NRestarts)" -le "$restarts0" ] && [ "$(now)" -lt "$end" ]; do sleep 1; done
wait_for fes-rt-core ActiveState active 30
say watchdog-log "$(journalctl -b --no-pager -u fes-rt-core.service | grep -c 'Watchdog timeout')"
state after-watchdog

# BindsTo: stopping the driver stops rt-core; ExecStopPost sends the safe stop.
systemctl stop fes-stim-driver.service
say stop-driver $?
state after-driver-stop
# journald writes late in the guest: wait up to 60 s for the ExecStopPost line.
safe_stops() { journalctl -b --no-pager -u fes-stim-driver.service | grep -c 'safe-stop: NMT stop written'; }
end=$(($(now) + 60)); while [ "$(safe_stops)" -lt 1 ] && [ "$(now)" -lt "$end" ]; do sleep 1; done
n1=$(safe_stops)
say safe-stop-log "$n1"

# A crashed driver: SIGKILL -> ExecStopPost safe stop again, restarted by on-failure.
systemctl start fes.target
wait_for fes-rt-core ActiveState active 60 || say fail "rt-core not back within 60 s"
state restarted
dpid=$(prop fes-stim-driver MainPID)
# MainPID 0 (no driver running) must not become kill(0): that would SIGKILL this script's
# own process group and leave the guest running until the host's timeout.
case "$dpid" in ''|0) say fail "no driver process to kill (MainPID '$dpid')"; dump_journal; finish ;; esac
kill -KILL "$dpid"
say killed-driver "$dpid"
end=$(($(now) + 30))
while [ "$(prop fes-stim-driver MainPID)" = "$dpid" ] || [ "$(prop fes-stim-driver ActiveState)" != active ]; do
  [ "$(now)" -ge "$end" ] && break; sleep 1; done
state after-driver-kill
end=$(($(now) + 60)); while [ "$(safe_stops)" -le "$n1" ] && [ "$(now)" -lt "$end" ]; do sleep 1; done
say safe-stop-log-2 "$(safe_stops)"

# The package's life cycle. Reinstall (dpkg's upgrade path): the operator's choices stay -
# fes.target disabled, an edited prescription (the new default goes beside it).
systemctl disable --quiet fes.target
echo "# operator's edit" >> /etc/fes/prescription.toml
dpkg -i "$FES_DEB" > /run/reinstall.log 2>&1
say reinstall $?
sed 's/^/reinstall-log: /' /run/reinstall.log
say enabled-after-reinstall "$(systemctl is-enabled fes.target)"
say prescription-kept "$(grep -c "operator's edit" /etc/fes/prescription.toml) $(test -f /etc/fes/prescription.toml.dist && echo dist)"
# Purge: prerm stops the stack (the driver's safe stop runs again), postrm removes the
# enablement links and runtime directories, keeps the recordings' /var/lib/fes.
n2=$(safe_stops)
dpkg --purge fes-stack-bench > /run/purge.log 2>&1
say purge $?
sed 's/^/purge-log: /' /run/purge.log
say after-purge-driver "$(systemctl is-active fes-stim-driver.service)"
end=$(($(now) + 30)); while [ "$(safe_stops)" -le "$n2" ] && [ "$(now)" -lt "$end" ]; do sleep 1; done
say safe-stop-log-3 "$(safe_stops)"
left=""
for f in /run/fes /etc/fes/rt-core.toml /etc/fes/prescription.toml /usr/bin/rt-core \
         /usr/lib/systemd/system/fes.target /etc/systemd/system/fes.target.wants; do
  if [ -e "$f" ]; then left="$left $f"; fi
done
say purge-left "${left:-none}"
say purge-kept "$(test -d /var/lib/fes && echo /var/lib/fes) $(getent passwd fes >/dev/null && echo user-fes)"
dump_journal
finish

# Shared by scripts/install (source install), scripts/package (the Debian packages) and the
# packages' systemd generator (/usr/lib/systemd/system-generators/fes-placement-generator,
# which sources it as /usr/lib/fes/units.sh): rendering the unit templates of systemd/, the
# default CPU placement and the checks of the values an engineer gives. POSIX sh, no
# bashisms: the generator runs under /bin/sh. Sourced, never run; defines functions only.
#
# Rendering uses the caller's variables:
#   bindir confdir docdir   where the binaries, the configuration and the docs are
#   iface                   the CAN interface (rig: the device unit fes-can.service waits for)
#   rt_cpus hk_cpus         CPUAffinity= of the real-time pair and of the housekeeping units
# Empty iface, rt_cpus and hk_cpus render a *static* unit, what a package ships: no device
# dependency and `CPUAffinity=` empty (no placement); the generator adds both as drop-ins
# from /etc/fes/can.env and /etc/fes/placement.env (docs/deployment.md, "The package").

# True when $1 is a CPU list as CPUAffinity= takes it: 1, 2-3, 1,3, "0 2".
fes_cpu_list_ok() {
  case "$1" in *'
'*) return 1 ;; esac
  printf '%s\n' "$1" | grep -Eqx '[0-9]+(-[0-9]+)?([, ][0-9]+(-[0-9]+)?)*'
}

# Checks a CAN interface name (Linux: at most 15 characters, no '/', no whitespace); on a
# bad one prints the reason on stdout and returns 1.
fes_iface_check() {
  case "$1" in
    '' | *[!A-Za-z0-9_.-]*) echo "bad interface name '$1'"; return 1 ;;
  esac
  if [ "${#1}" -gt 15 ]; then
    echo "interface name '$1' is longer than 15 characters"; return 1
  fi
  return 0
}

# Sets rt_cpus and hk_cpus where they are empty: the last online CPU for real time, the
# others for housekeeping (CPU 0 for both, with a warning on stderr, on a one-CPU machine).
# $fes_prog prefixes the warning.
fes_default_cpus() {
  _ncpu=$(getconf _NPROCESSORS_ONLN)
  _last=$((_ncpu - 1))
  if [ -z "$rt_cpus" ]; then rt_cpus=$_last; fi
  if [ -z "$hk_cpus" ]; then
    if [ "$_ncpu" -ge 2 ]; then
      if [ "$_last" -ge 2 ]; then hk_cpus="0-$((_last - 1))"; else hk_cpus=0; fi
    else
      hk_cpus=0
      echo "${fes_prog:-fes}: WARNING: one CPU only: real-time and housekeeping share CPU 0" >&2
    fi
  fi
}

# Renders the unit template $1 into $2 (mode 0644); returns 1, saying so on stderr, when a
# placeholder is left.
fes_render() {
  if [ -n "$iface" ]; then
    _dev="s#@CAN_IFACE@#$iface#g"
  else
    # Static: the device dependency (and the name in the description) come from a drop-in.
    _dev='/sys-subsystem-net-devices-@CAN_IFACE@\.device/d; s# @CAN_IFACE@##g'
  fi
  sed -e "s#@BINDIR@#$bindir#g; s#@CONFDIR@#$confdir#g; s#@DOCDIR@#$docdir#g" -e "$_dev" \
    -e "s#@RT_CPUS@#$rt_cpus#g; s#@HOUSEKEEPING_CPUS@#$hk_cpus#g" "$1" > "$2" || return 1
  if grep -q '@[A-Z_]*@' "$2"; then
    echo "unrendered placeholder in $2" >&2
    return 1
  fi
  chmod 0644 "$2"
}

# The units of a variant (rig or bench) as "installed-name:template" pairs, in the order
# scripts/install renders them.
fes_units_of() {
  echo "fes.target:fes.target fes-can-netns.service:fes-can-netns.service"
  echo "fes-stim-driver.service:fes-stim-driver.service fes-rt-core.service:fes-rt-core.service"
  echo "fes-supervisor.service:fes-supervisor.service"
  if [ "$1" = rig ]; then
    echo "fes-can.service:fes-can.service"
  else
    echo "fes-can.service:fes-vcan.service fes-sim-muscle.service:fes-sim-muscle.service"
  fi
}

"""A session run through the RT process, from a client's side (the command line, scripts):
take control, send the protocol, heartbeat while it runs, follow its progress, return the
summary. Qt-free; the GUI has its own worker around the same RT client."""
from __future__ import annotations

import sys
import time
from typing import Any

from rt.errors import InputError, ProtocolValidationError


def run_remote(endpoint: str, document: dict[str, Any], patient: dict[str, Any],
               record: dict[str, Any], progress=None, poll_s: float = 0.2) -> dict[str, Any]:
    """Run one session in the RT process at ``endpoint``; returns its summary.

    Raises:
        ProtocolValidationError: the RT process refused the session (validation, pre-flight,
            limits), with its reason.
    """
    from rt.ipc.client import RtClient, default_client_id

    with RtClient(endpoint, client_id=default_client_id("session"), timeout_s=2.0) as client:
        client.control_acquire(f"talus session run ({patient['id']})")
        client.start_heartbeat(0.05)
        try:
            try:
                started = client.session_start(document, patient, record)
            except InputError as exc:
                raise ProtocolValidationError(str(exc)) from None
            sid = started["session_id"]
            while True:
                st = client.session_status()
                if st["session"] == sid:
                    if progress is not None:
                        progress(float(st["progress"]))
                    time.sleep(poll_s)
                    continue
                last = st.get("last_summary")
                if last is None or last.get("session_id") != sid:
                    raise InputError(f"session {sid} ended without a summary")
                if progress is not None:
                    progress(1.0)
                return last
        finally:
            client.stop_heartbeat()
            try:
                client.control_release()
            except InputError:
                pass       # the session is still stopping: control lapses with the heartbeat


def progress_bar(stream=sys.stderr):
    def show(fraction: float) -> None:
        n = int(fraction * 40)
        stream.write(f"\r[{'#' * n}{'.' * (40 - n)}] {fraction * 100:5.1f} %")
        stream.flush()
        if fraction >= 1.0:
            stream.write("\n")
    return show


def print_summary(s: dict) -> None:
    w = sys.stdout.write
    where = f"RT process pid {s['rt']['pid']}" if s.get("rt") else "the twin"
    w(f"session: {s['protocol']} ({s['kind']}) by {where} on the twin — {s['outcome']}\n")
    if s["rms_error_pct"] is not None:
        w(f"  force RMS error   {s['rms_error_pct']:.2f} % of {s['rms_error_basis']}\n")
    if s["peak_force_n"] is not None:
        w(f"  peak force        {s['peak_force_n']:.1f} N\n")
    if s.get("min_force_n") is not None:
        w(f"  least force       {s['min_force_n']:.1f} N (in contact, force control)\n")
    src = s.get("source")
    if src:
        plate = "" if src["plate_index"] is None else f", plate {src['plate_index']}"
        off = src["offset_removed_n"]["fz"]
        w(f"  source            {src['source']}{plate} (sha256 "
          f"{(src['source_sha256'] or '?')[:16]}…)\n"
          f"                    stance {src['stance_window_s'][0]:.3f} .. "
          f"{src['stance_window_s'][1]:.3f} s, "
          + (f"offset removed {off:.2f} N" if src["offset_measured"] else "offset not measured")
          + f", scale {src['scale_factor']:.4f}, source body mass "
          f"{src['source_body_mass_kg']:g} kg ({src['source_body_mass_from']})\n")
    for axis, rng in s["rom_deg"].items():
        if rng:
            w(f"  {axis:5s} reached    {rng[0]:+.1f} .. {rng[1]:+.1f} deg\n")
    w(f"  stops             {len(s['stops'])}"
      + "".join(f"\n    t={x['t']} s {x['reaction']}: {x['cause']} ({x['message']})"
                for x in s["stops"]) + "\n")
    for a in s.get("alarms") or ():
        # What the staff had to act on (a pull the robot could not end), and whether it ended.
        end = ("still raised at the end" if a.get("ended_t") is None
               else f"ended t={a['ended_t']} s ({a.get('how')})")
        w(f"  ALARM             t={a['t']} s {a['cause']}: {a['message']}; {end}\n")
    if s.get("recording"):
        w(f"  recording         {s['recording']['path']} (sha256 "
          f"{s['recording']['sha256'][:16]}…)\n")
    pre = s["preflight"]
    w(f"  pre-flight peaks  actuator {pre['peak_actuator_force_n']:.0f} N, slider "
      f"{pre['peak_slider_speed_m_s'] * 1e3:.0f} mm/s\n")
    for lim in pre.get("at_robot_limit") or ():
        # Beyond the robot, if briefly: the force there is what the drives give, not the
        # protocol's.
        play = lim.get("from_play_s")
        w(f"  beyond the robot  {lim['what']} {lim['peak']:.4g} {lim['unit']} asked, limit "
          f"{lim['limit']:g} {lim['unit']}, {lim['longest_s'] * 1e3:.0f} ms from t = "
          f"{lim['from_s']:.3f} s"
          + ("" if play is None else f" ({play:.3f} s into the protocol)") + "\n")
    sat = pre.get("drive_saturation")
    if isinstance(sat, dict) and sat.get("peak_s", 0.0) > 0.0:
        # How close that came to the sustained-saturation stop.
        w(f"  drives saturated  at most {sat['peak_s'] * 1e3:.0f} ms in any "
          f"{sat['window_s']:g} s (the robot stops beyond {sat['stops_beyond_s'] * 1e3:.0f} ms)"
          "\n")

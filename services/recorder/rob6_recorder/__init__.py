"""rob6 recorder service and session-log tools (MCAP).

Library API (the service in ``service.py`` feeds ``Recorder``):

* ``rob6_recorder.writer``: ``Recorder`` (non-blocking ``submit``, per-session files,
  rolling system file); the files are written by ``rob6_recorder_native.Writer`` (Rust,
  services/recorder/native), ``payloads`` makes a record's JSON, ``derived_channels`` the
  /tf and /flange derived from joint states (computed by ``transforms``).
* ``rob6_recorder.reader``: ``read_records`` / ``scan`` (also unfinished files).
* ``rob6_recorder.recover``: ``recover(path, out_path)``.
* ``rob6_recorder.inspect``: ``summarize``, ``export_csv``.
* ``rob6_recorder.session_replay``: ``load_script``, ``replay`` (a client session against a server).
* ``rob6_recorder.playback``: ``play`` (into the live view), ``replay_joints``.
* ``rob6_recorder.cli``: the ``rob6-log`` click commands.
"""

__version__ = "0.1.0"

"""Replay: episodes as data, rerun recordings, stills and videos (docs/replay.md).

Replay is decoupled from the simulation (docs/architecture.md rule 13). The simulation
side records plain arrays (:class:`EpisodeBuffer`, the episode file of
:func:`save_episode`, the trace file of :mod:`cnt_env.io`) as :class:`Frame` s; one logger
turns frames into a rerun recording, either frame by frame (a live viewer) or column by
column (``send_columns``, for files: the same recording at a fraction of the cost). So an
episode recorded by the wrapper (:class:`RerunRecorder`), a saved episode
(:func:`record_episode`), a saved run (:func:`record_simulation`) and a run recorded as
it goes (:func:`record_run`) all give the same entities. rerun is imported only when a
recording is made: importing this package, or using :class:`EpisodeSaver` and the
episode file, never imports it. Install it with ``pip install -e ".[rerun]"``
(rerun-sdk 0.41).

==================  =================================================================
module              job
==================  =================================================================
``episode``         :class:`Frame`, :class:`Episode` (validated arrays), the episode
                    file (:func:`save_episode`, :func:`load_episode`); no rerun, no gym
``wrappers``        :class:`EpisodeBuffer`, :class:`EpisodeSaver`: gym wrappers, no rerun
``rerun``           :func:`import_rerun`, the stream, the scene logger, the blueprint
``recorder``        :class:`RerunRecorder`, :func:`record_episode`
``simulation``      runs: :func:`record_simulation` (saved), :class:`RunRecording` and
                    :func:`record_run` (as it goes)
``rrd``             :func:`read_rrd`: what a recording holds
``still``           :func:`render_top_view`: a PNG of one frame (matplotlib)
``video``           :func:`write_video`: a GIF or MP4 of an episode or a saved run
                    (the ``[video]`` extra)
==================  =================================================================

Recordings
----------
One ``RecordingStream`` per episode or run, with an explicit recording id (episodes:
``"<tag>-s<seed>-e<episode>"``) and no automatic timelines and properties: no
``log_time`` (wall clock) timeline and no start-time property, so that the same data
give the same recording. Timelines:

* ``step``: sequence. Episodes: the control step (0 = the state after reset). Runs: the
  physics step.
* ``sim_time``: duration, in tau (time unit mu L_vb^2 / e_v, units.py), shown by the
  viewer as seconds: 1 s = 1 tau. Episodes: since reset; runs: since the start.
* ``trace_node`` (saved runs only, :func:`record_simulation`): the number of trace
  nodes shown, for a trace without a time history.

Entities (lengths in L_vb; the substrate is the x-z plane, y up):

======================  ======================  ===================================
entity                  archetype               content
======================  ======================  ===================================
``world``               ViewCoordinates         right-handed, y up (static)
``world/substrate``     LineStrips3D            outline of the substrate (static)
``world/target``        LineStrips3D            target path at y = 0 (static)
``world/trace_before``  LineStrips3D            trace laid before reset (static)
``world/trace``         LineStrips3D            trace laid since reset (runs: all)
``world/rod``           LineStrips3D            the suspended rod, contact to top
``world/flow``          Arrows3D                flow velocity at the contact point
``world/pads``          LineStrips3D            a route's pads (static)
``world/keepouts``      LineStrips3D            a route's keep-out polygons (static)
``top/...``             LineStrips2D, Arrows2D  the same seen from above: (x, z)
``top/corridor``        LineStrips2D            a route's corridor: half-width w (static)
``reward/total``        Scalars                 the reward ``step`` returned
``reward/<term>``       Scalars                 ``info["reward_<term>"]``
``reward/return``       Scalars                 the return so far
``score/...``           Scalars                 score, coverage, precision, progress
``metrics/...``         Scalars                 the other numeric ``info`` entries
``pattern/...``         Scalars                 ``info["pattern"]`` measures, if any
``solver/...``          Scalars                 physics steps and Newton iterations
``flow/vbar``, ``phi``  Scalars                 flow speed (e_v/(mu H)) and angle
``events``              TextLog                 reset, failures, the episode's end
======================  ======================  ===================================

Each series' ``SeriesLines`` style is logged once, static. The default blueprint
(:func:`default_blueprint`) shows a 3D view, the top view and the plots.

The episode file (``format`` ``"cnt_env.episode"``, version 1) is described at
:func:`save_episode`. Open a recording with ``rerun FILE.rrd``.
"""

from __future__ import annotations

from cnt_env.plotting import FLOW_ARROW_FRACTION
from cnt_env.replay.episode import (
    APPLICATION_ID,
    EPISODE_FORMAT,
    EPISODE_FORMAT_VERSION,
    Episode,
    EpisodeFileError,
    Frame,
    file_format,
    load_episode,
    save_episode,
)
from cnt_env.replay.recorder import RerunRecorder, record_episode
from cnt_env.replay.rerun import INSTALL_HINT, MODES, default_blueprint, import_rerun
from cnt_env.replay.rrd import read_rrd
from cnt_env.replay.simulation import (
    RUN_FRAMES,
    SAVED_RUN_FRAMES,
    RunRecording,
    record_run,
    record_simulation,
)
from cnt_env.replay.still import render_top_view
from cnt_env.replay.video import (
    VIDEO_FORMATS,
    VIDEO_INSTALL_HINT,
    episode_frames,
    import_imageio,
    trace_frames,
    write_video,
)
from cnt_env.replay.wrappers import (
    EpisodeBuffer,
    EpisodeSaver,
    _simulator,  # noqa: F401  (the env's DepositionSim; tests read it)
    episode_recording_id,
)

__all__ = [
    "APPLICATION_ID",
    "EPISODE_FORMAT",
    "EPISODE_FORMAT_VERSION",
    "FLOW_ARROW_FRACTION",
    "INSTALL_HINT",
    "MODES",
    "RUN_FRAMES",
    "SAVED_RUN_FRAMES",
    "VIDEO_FORMATS",
    "VIDEO_INSTALL_HINT",
    "Episode",
    "EpisodeBuffer",
    "EpisodeFileError",
    "EpisodeSaver",
    "Frame",
    "RerunRecorder",
    "RunRecording",
    "default_blueprint",
    "episode_frames",
    "episode_recording_id",
    "file_format",
    "import_imageio",
    "import_rerun",
    "load_episode",
    "read_rrd",
    "record_episode",
    "record_run",
    "record_simulation",
    "render_top_view",
    "save_episode",
    "trace_frames",
    "write_video",
]

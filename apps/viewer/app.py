"""The interactive viewer's loop: native MuJoCo, live damage feedback, a policy or a person at the keys.

Each control step (one ``env.dt``, e.g. 24 ms):

1. keys pressed since the last step (:mod:`apps.viewer.keys`) change the
   teleoperation command, pause, reset, end the episode, or the speed;
2. the action comes from the policy (``policy(state, rng)``, jitted) or the
   latched teleoperation command;
3. :func:`apps.viewer.native_env.step` advances the ``MjData`` the viewer shows
   (the task's own step, native physics, temperature, liquid and damage at
   every substep), under the viewer's lock;
4. feedback (:mod:`apps.viewer.feedback`): geom colours by health, the
   liquid, the heat-source glow; then ``viewer.sync()``; the one overlay, the
   health panel (bars, values, episode cost, damage per model of the last
   second; status lines under it; status only with feedback off) is drawn and
   handed to the viewer on a thread of its own (:func:`_panel_worker`);
5. with ``record``, the step joins the episode's rows; an episode ends after
   ``episode_length`` steps or on Enter and is appended to the dataset file;
6. the loop sleeps until wall clock = simulated time / speed (slow motion:
   speed < 1). A step that falls behind does not make the next ones hurry: the
   clock restarts from it (so a pause or a stall never turns into a fast-forward).

The viewer's render thread runs at a lower priority (nice +10): where the CPU
is short (software OpenGL under Xvfb draws as fast as it can), frames drop
before control steps slow.

``run`` returns what happened (steps, episodes, wall and simulated time, the
wall and CPU time (this thread's) of each control step from action to
``sync`` (pacing sleeps excluded), the first and last panel, the screenshot) for the command line, the
tests and the benchmark.
"""

from __future__ import annotations

import collections
import os
import queue
import threading
import time
from typing import Callable, Optional

import jax
import mujoco
import mujoco.viewer
import numpy as np

from apps.viewer import display as X
from apps.viewer import episode as EP
from apps.viewer import feedback as F
from apps.viewer import keys as K
from apps.viewer import native_env as N
from mjx_damage import render

SETTLE_S = 2.0  # s a screenshot waits at most for two equal reads of the screen
LATE_S = 0.25  # a step this far behind the wall clock restarts the clock instead of catching up


def _status(mode: str, paused: bool, speed: float, ep: int, t: int, length: int, record: Optional[str],
            recorded: int) -> list:
  """Status lines under the damage panel."""
  lines = [f"{mode}{'   PAUSED (Space)' if paused else ''}",
           f"episode {ep}, step {t} / {length}   speed {speed:g}x real time (- / =)"]
  if record:
    lines.append(f"recording: {os.path.basename(record)} ({recorded} episodes in the file)")
  return lines


def _panel_worker(viewer, sc: F.Scene, feedback: bool, drawn: list):
  """Draw the health panel and hand it to the viewer on a thread of its own.

  ``Handle.set_images`` (as ``set_texts``) returns only after the viewer's
  render thread took the image (one rendered frame: 10-200 ms in software GL), so the control loop posts the latest numbers and
  never waits for a frame; a panel not yet drawn when newer numbers arrive is
  dropped (the screen shows every frame the newest state). Returns ``post(frame,
  recent, status)``, ``flush()`` (wait until the frame showing the last posted state is on
  screen) and ``stop()``.
  """
  latest: queue.Queue = queue.Queue(maxsize=1)
  stop = threading.Event()

  def loop():
    while not stop.is_set():
      try:
        fr, recent, status = latest.get(timeout=0.05)
      except queue.Empty:
        continue
      img = F.panel(sc, fr, recent, status, feedback)
      drawn[:] = [drawn[0] if drawn else img, img]
      vp = viewer.viewport
      top = vp.height if vp is not None and vp.height > 0 else img.shape[0]
      viewer.set_images((mujoco.MjrRect(0, max(0, top - img.shape[0]), img.shape[1], img.shape[0]), img))
      latest.task_done()

  worker = threading.Thread(target=loop, name="mjx-damage-panel", daemon=True)
  worker.start()

  last = []

  def post(fr, recent, status):
    last[:] = [(fr, recent, status)]
    try:  # only this thread puts: after dropping a stale panel there is room
      latest.get_nowait()
      latest.task_done()
    except queue.Empty:
      pass
    latest.put_nowait((fr, recent, status))

  def halt():
    stop.set()
    worker.join(timeout=5.0)

  def flush():
    # the last panel taken starts a frame; taking it once more starts the next, so the frame
    # showing the last posted state (scene and panel) is on screen when this returns
    latest.join()
    if last:
      post(*last[0])
      latest.join()

  return post, flush, halt


RENDER_NICE = 10  # niceness of the viewer's render thread: frames drop before control steps slow


def _yield_to_simulation(threads) -> None:
  """Lower the viewer's render thread(s) to nice ``RENDER_NICE`` (Linux: per-thread priority).

  Under Xvfb the software renderer draws as fast as it can; on a busy CPU it would take time
  from the control loop, which must keep real time, while a dropped frame costs nothing."""
  for th in threads:
    try:
      os.setpriority(os.PRIO_PROCESS, th.native_id, RENDER_NICE)
    except (AttributeError, OSError, TypeError):  # not Linux, or not permitted: keep the default
      pass


def _window(img: np.ndarray, viewer) -> np.ndarray:
  """The viewer window's part of a screenshot (no window manager: the window sits at the screen's origin)."""
  vp = viewer.viewport
  if vp is None or vp.width <= 0 or vp.height <= 0:
    return img
  return img[: vp.height, : vp.width]


def _frame_camera(cam: mujoco.MjvCamera, nat: N.NativeEnv, data: mujoco.MjData, sc: F.Scene) -> None:
  """Point the viewer's free camera at the tracked bodies and heat sources, as rendered videos frame them."""
  bodies = np.unique(np.asarray(nat.binding.link_body))
  sources = sc.source_geom if sc.source_geom is not None else ()
  framed = render.camera_of(nat.model, data, None, bodies, sources)
  cam.type = mujoco.mjtCamera.mjCAMERA_FREE
  cam.lookat[:] = framed.lookat
  cam.distance, cam.azimuth, cam.elevation = framed.distance, framed.azimuth, framed.elevation


def initial_grip(env) -> Callable:
  """``grip(state) -> float``: the gripper command the task starts with, its scripted safe policy's
  first action (0 for an env without one), compiled once."""
  task = env.unwrapped
  if env.action_size == 0 or not hasattr(task, "policy"):
    return lambda state: 0.0
  safe = jax.jit(task.policy("safe"))
  return lambda state: float(np.asarray(safe(state, jax.random.PRNGKey(0)))[-1])


def run(env, task: str, *, policy: Optional[Callable] = None, feedback: bool = True, record: Optional[str] = None,
        env_config: Optional[dict] = None, label: str = "teleop", episode_length: int, steps: Optional[int] = None,
        episodes: Optional[int] = None, seed: int = 0, realtime: bool = True, speed: float = 1.0,
        screen: Optional[X.Display] = None, shots: tuple = (), plain: bool = False, log=print) -> dict:
  """Open the viewer on ``env`` (one damage-wrapped env of the suite) and run until the window closes,
  ``steps`` control steps or ``episodes`` episodes. ``screen``: the
  :func:`apps.viewer.display.virtual_display` the viewer runs on; its screen before the viewer
  closes comes back as ``result["screenshot"]`` (uint8[H, W, 3]), and after each step count in
  ``shots`` (0: the reset state) as ``result["shots"][k]``. ``plain``: no shadows or
  reflections (software OpenGL, as under Xvfb, renders several times faster without them)."""
  nat = N.make(env)
  data = mujoco.MjData(nat.model)
  sc = F.scene(nat.binding, nat.model, nat.dt, feedback)
  if plain:
    nat.model.light_castshadow[:] = 0
    nat.model.mat_reflectance[:] = 0
  events: queue.SimpleQueue = queue.SimpleQueue()
  act = jax.jit(policy) if policy is not None else None
  rng = jax.random.PRNGKey(seed)
  mode = label if policy is not None else "teleop (keys: mjx-damage view --help)"
  recorded = EP.check_target(record, task) if record else 0
  safe_threshold = float(getattr(env, "safe_threshold", 95.0))

  grip = initial_grip(env) if policy is None else (lambda state: 0.0)
  ep, t, total = 0, 0, 0
  state = N.reset(nat, data, jax.random.fold_in(rng, ep))
  teleop = K.start(env.action_size, grip(state))
  rows, recent = [], collections.deque(maxlen=sc.window)
  paused = False
  before = set(threading.enumerate())
  viewer = mujoco.viewer.launch_passive(nat.model, data, key_callback=events.put, show_left_ui=False,
                                        show_right_ui=False)
  _yield_to_simulation(set(threading.enumerate()) - before)
  panels: list = []  # [first, last] panel images drawn
  post_panel, flush_panel, stop_panel = _panel_worker(viewer, sc, feedback, panels)
  _frame_camera(viewer.cam, nat, data, sc)
  clock_wall, clock_sim = time.perf_counter(), 0.0
  t_start = clock_wall
  shot, step_s, step_cpu_s, taken = None, [], [], {}

  def take(k):
    if screen is not None and k in shots:
      flush_panel()
      taken[k] = _window(X.screenshot(screen, settle_s=SETTLE_S), viewer)

  def show(fr):
    with viewer.lock():
      nat.model.geom_rgba[:] = F.colours(sc, fr, feedback)
      F.add_particles(viewer.user_scn, sc, fr)
    post_panel(fr, np.sum(np.asarray(recent), axis=0) if recent else np.zeros(3, np.float32),
               _status(mode, paused, speed, ep, t, episode_length, record, recorded))
    viewer.sync()

  def save_episode():
    nonlocal recorded
    if record and rows:
      ds = EP.to_dataset(rows, task=task, entity_names=env.entity_names, env_config=env_config or {},
                         label=label, safe_threshold=safe_threshold)
      index = EP.write(record, ds, feedback)
      recorded += 1
      log(f"episode {ep}: {len(rows)} steps appended to {record} as demo_{index} (feedback {feedback})")

  def new_episode():
    nonlocal ep, t, state, teleop, rows, clock_wall, clock_sim
    ep, t, rows = ep + 1, 0, []
    recent.clear()
    with viewer.lock():
      state = N.reset(nat, data, jax.random.fold_in(rng, ep))
    teleop = K.start(env.action_size, grip(state))
    clock_wall, clock_sim = time.perf_counter(), 0.0

  show(F.frame(state, sc.ambient))
  take(0)
  try:
    while viewer.is_running():
      while not events.empty():
        key = events.get()
        if key in K.PAUSE:
          paused = not paused
        elif key in K.RESET:  # the viewer resets the MjData itself on Backspace; the env reset follows
          new_episode()
        elif key in K.END_EPISODE:
          save_episode()
          new_episode()
        elif key in K.SLOWER + K.FASTER:
          speed = K.speed_after(speed, key)
        else:
          teleop = K.press(teleop, key)
        clock_wall, clock_sim = time.perf_counter(), 0.0
      if paused:
        show(F.frame(state, sc.ambient))
        time.sleep(0.03)
        continue
      if act is not None:
        action = np.asarray(act(state, jax.random.fold_in(jax.random.fold_in(rng, ep), t)))
      else:
        action = teleop.action
      t_step, c_step = time.perf_counter(), time.thread_time()
      obs, qpos, qvel = np.asarray(state.obs), data.qpos.copy(), data.qvel.copy()
      with viewer.lock():
        nxt = N.step(nat, data, state, action)
      if record:
        rows.append(EP.step_record(obs, qpos, qvel, action, nxt))
      state, t, total = nxt, t + 1, total + 1
      fr = F.frame(state, sc.ambient)
      recent.append(fr.damage)
      show(fr)
      step_s.append(time.perf_counter() - t_step)
      step_cpu_s.append(time.thread_time() - c_step)
      take(total)
      if t >= episode_length or (steps is not None and total >= steps):
        save_episode()
        if (steps is not None and total >= steps) or (episodes is not None and ep + 1 >= episodes):
          break  # the last state stays on screen (and in the result)
        new_episode()
      if realtime:
        clock_sim += nat.dt / speed
        lag = time.perf_counter() - clock_wall - clock_sim
        if lag < 0:
          time.sleep(-lag)
        elif lag > LATE_S:
          clock_wall, clock_sim = time.perf_counter(), 0.0
    wall = time.perf_counter() - t_start
    if screen is not None:
      flush_panel()
      shot = _window(X.screenshot(screen, settle_s=SETTLE_S), viewer)
  finally:
    wall = time.perf_counter() - t_start if shot is None else wall
    stop_panel()
    viewer.close()
    time.sleep(0.3)  # the render thread leaves its loop within a frame
  return {"steps": total, "episodes": ep + (t > 0), "wall_s": wall, "sim_s": total * nat.dt, "recorded": recorded,
          "first_panel": panels[0] if panels else None,
          "last_panel": panels[-1] if panels else None, "screenshot": shot, "shots": taken, "scene": sc,
          "step_s": step_s, "step_cpu_s": step_cpu_s,
          "final_health": dict(zip(env.entity_names, np.asarray(state.info["entity_health"]).tolist()))}

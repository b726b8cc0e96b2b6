"""The page's script (JavaScript, run after meshcat's): build the scene, frame it, follow time.

It replays the scene's commands in order (``#sjt-scene``, base64 msgpack) and sizes the view to
its pane. If the page has a view direction (``#sjt-meta``), it puts the camera on that side of
the scene, just far enough that every vertex of the scene fits the view with a margin, at
``FRAME_SAMPLES + 1`` times spread over the animation (a robot that rises during its run stays
inside); it does so again when the window is resized, until the user turns the camera. The
desired paths' dots (``meta.dots``) are then sized in pixels of that view (:data:`DOT_PIXELS`,
at most :data:`DOT_GAP` of their spacing on screen), so they neither vanish in a wide scene nor
hide the path followed. meshcat's own controls ("Open Controls") move from the top of the view
to the bottom of the side panel. Each animation frame it then:

- moves a tag over each robot with its label and the method being replayed;
- highlights that run in the robot's legend;
- moves the dashed cursor in the robot's error plot to the time reached in that run;
- updates the time slider and clock.

The play button and the slider drive meshcat's animator; ``window.viewer`` is meshcat's viewer.
"""

SCRIPT_TEMPLATE = r"""
"use strict";
(function () {
  const meta = JSON.parse(document.getElementById("sjt-meta").textContent);
  const THREE = MeshCat.THREE;
  const pane = document.getElementById("meshcat-pane");
  const view = document.getElementById("view");
  const viewer = new MeshCat.Viewer(pane);
  window.viewer = viewer;
  const FRAME_SAMPLES = @SAMPLES@, FRAME_MARGIN = @MARGIN@, DOT_PIXELS = @DOT@,
    DOT_GAP = @GAP@;
  const gui = viewer.gui.domElement;  // meshcat's "Open Controls": under the panel, not the view
  const panel = document.getElementById("panel");
  if (panel) {
    panel.appendChild(gui);
    gui.style.position = "static";
    gui.classList.add("meshcat-controls");
  }

  // meshcat sizes its view to the window's height; size it to its pane instead
  const setSize = viewer.set_3d_pane_size.bind(viewer);
  viewer.set_3d_pane_size = (w, h) =>
    setSize(w === undefined ? pane.clientWidth : w, h === undefined ? pane.clientHeight : h);
  viewer.set_3d_pane_size();

  for (const text of JSON.parse(document.getElementById("sjt-scene").textContent)) {
    const raw = atob(text);
    const bytes = new Uint8Array(raw.length);
    for (let i = 0; i < raw.length; i++) bytes[i] = raw.charCodeAt(i);
    viewer.handle_command_bytearray(bytes);
  }
  viewer.animator.seek(0);  // pose the robots as at t = 0 (meshcat waits for the next frame)

  // -- camera: frame every vertex of the scene from the direction meta.view ----------------
  let userMoved = false;
  viewer.controls.addEventListener("start", () => { userMoved = true; });

  function sceneVertices(frame) {
    const points = [];
    const root = viewer.scene_tree.find(["meshcat"]).object;
    viewer.scene.updateMatrixWorld(true);
    root.traverse((object) => {
      const position = object.geometry && object.geometry.attributes &&
        object.geometry.attributes.position;
      if (!position || !object.visible) return;
      const v = new THREE.Vector3();
      for (let i = 0; i < position.count; i++) {
        v.fromBufferAttribute(position, i).applyMatrix4(object.matrixWorld);
        points.push(frame.worldToLocal(v.clone()));
      }
    });
    return points;
  }

  function framedVertices(frame) {  // the scene's vertices at times spread over the animation
    const actions = viewer.animator.actions;
    if (actions.length === 0) return sceneVertices(frame);
    const now = actions[0].time;
    const duration = Math.max(...actions.map((action) => action.getClip().duration));
    const points = [];
    for (let k = 0; k <= FRAME_SAMPLES; k++) {
      viewer.animator.seek((duration * k) / FRAME_SAMPLES);
      for (const point of sceneVertices(frame)) points.push(point);
    }
    viewer.animator.seek(now);
    return points;
  }

  function onScreen(points) {  // median spacing (pixels) and depth (m) of a Points' dots
    const position = points.geometry.attributes.position;
    const a = new THREE.Vector3(), b = new THREE.Vector3(), gaps = [], depths = [];
    const median = (values) => values.sort((x, y) => x - y)[Math.floor(values.length / 2)];
    for (let i = 0; i < position.count; i++) {
      a.fromBufferAttribute(position, i).applyMatrix4(points.matrixWorld)
        .applyMatrix4(viewer.camera.matrixWorldInverse);
      depths.push(-a.z);
      a.applyMatrix4(viewer.camera.projectionMatrix);
      if (i > 0) {
        gaps.push(Math.hypot((a.x - b.x) * pane.clientWidth, (a.y - b.y) * pane.clientHeight) / 2);
      }
      b.copy(a);
    }
    return {gap: gaps.length ? median(gaps) : Infinity, depth: median(depths)};
  }

  function sizeDots() {  // the desired paths' dots: DOT_PIXELS wide, or less where they are dense
    viewer.camera.updateMatrixWorld();
    viewer.scene.updateMatrixWorld(true);
    for (const path of meta.dots || []) {
      const node = viewer.scene_tree.find(["meshcat", ...path.split("/")]).object;
      node.traverse((o) => {
        if (!o.isPoints) return;
        const {gap, depth} = onScreen(o);
        const pixels = Math.max(1.5, Math.min(DOT_PIXELS, DOT_GAP * gap));
        // three.js draws a point size * (height / 2) / depth pixels wide
        o.material.size = (2 * pixels * Math.max(depth, 1e-3)) / Math.max(pane.clientHeight, 1);
      });
    }
  }

  function frameScene() {
    const camera = viewer.camera;
    const points = framedVertices(camera.parent);  // in the camera's frame: y up, world z
    if (points.length === 0) return;
    const center = new THREE.Box3().setFromPoints(points).getCenter(new THREE.Vector3());
    const [x, y, z] = meta.view;
    const back = new THREE.Vector3(x, z, -y).normalize();  // world (x, y, z) is (x, z, -y)
    const right = new THREE.Vector3().crossVectors(camera.up, back).normalize();
    const up = new THREE.Vector3().crossVectors(back, right);
    const tanV = Math.tan(THREE.MathUtils.degToRad(camera.fov / 2));
    const tanH = tanV * camera.aspect;
    const p = new THREE.Vector3();
    let distance = 0;
    for (let pass = 0; pass < 3; pass++) {  // fit the distance, then centre the picture
      distance = 0;
      for (const point of points) {
        p.subVectors(point, center);
        const depth = p.dot(back);
        distance = Math.max(distance, depth + Math.abs(p.dot(right)) / tanH,
                            depth + Math.abs(p.dot(up)) / tanV);
      }
      const seen = {left: Infinity, right: -Infinity, bottom: Infinity, top: -Infinity};
      for (const point of points) {  // where the points fall, as tangents of view angles
        p.subVectors(point, center);
        const depth = distance - p.dot(back);
        seen.left = Math.min(seen.left, p.dot(right) / depth);
        seen.right = Math.max(seen.right, p.dot(right) / depth);
        seen.bottom = Math.min(seen.bottom, p.dot(up) / depth);
        seen.top = Math.max(seen.top, p.dot(up) / depth);
      }
      center.addScaledVector(right, distance * (seen.left + seen.right) / 2)
            .addScaledVector(up, distance * (seen.bottom + seen.top) / 2);
    }
    camera.position.copy(center).addScaledVector(back, FRAME_MARGIN * distance);
    viewer.controls.target.copy(center);
    viewer.controls.update();
    sizeDots();
    viewer.set_dirty();
  }

  if (meta.view) {
    viewer.camera.fov = 40;  // meshcat's 75 degrees bend the robots at the sides of the view
    viewer.camera.updateProjectionMatrix();
    frameScene();
    window.addEventListener("resize", () => { if (!userMoved) frameScene(); });
  }

  // -- tags over the robots ------------------------------------------------------------------
  const robots = meta.robots.map((robot) => {
    const tag = document.createElement("div");
    tag.className = "tag";
    tag.dataset.robot = robot.node;
    const name = document.createElement("b");
    name.textContent = robot.label;
    const dot = document.createElement("span");
    dot.className = "dot";
    const method = document.createElement("span");
    tag.append(name, " ", dot, " ", method);
    view.appendChild(tag);
    const visuals = viewer.scene_tree.find(["meshcat", robot.node, "visuals"]).object;
    const section = document.querySelector(`section.robot[data-robot="${CSS.escape(robot.node)}"]`);
    return {robot, tag, dot, method, visuals,
            items: section ? Array.from(section.querySelectorAll("li[data-method]")) : [],
            plot: section ? section.querySelector("svg.error-plot") : null};
  });

  // -- play controls -----------------------------------------------------------------------
  const animator = viewer.animator;
  const play = document.getElementById("play");
  const slider = document.getElementById("time");
  const clock = document.getElementById("clock");
  let dragging = false;
  if (play) {
    play.addEventListener("click", () => {
      if (animator.playing) animator.pause(); else animator.play();
      play.textContent = animator.playing ? "Pause" : "Play";
    });
    slider.addEventListener("input", () => {
      dragging = true;
      animator.pause();
      animator.seek(parseFloat(slider.value));
    });
    slider.addEventListener("change", () => { dragging = false; });
  }
  const reset = document.getElementById("reset-view");
  if (reset) {
    reset.addEventListener("click", () => {
      userMoved = false;
      frameScene();
    });
  }

  function runAt(runs, t) {  // index of the last run started at time t (s), or -1
    let k = -1;
    runs.forEach((run, i) => { if (t >= run.start) k = i; });
    return k;
  }

  function follow() {
    const t = animator.actions.reduce((m, action) => Math.max(m, action.time), 0);
    if (play) {
      play.textContent = animator.playing ? "Pause" : "Play";
      if (!dragging) slider.value = t;
      clock.textContent = `${t.toFixed(1)} / ${parseFloat(slider.max).toFixed(1)} s`;
    }
    viewer.camera.updateMatrixWorld();
    const width = pane.clientWidth, height = pane.clientHeight;
    for (const r of robots) {
      const k = runAt(r.robot.runs, t);
      const run = k >= 0 ? r.robot.runs[k] : null;
      r.dot.style.background = run ? run.color : "transparent";
      r.method.textContent = run ? run.method.toUpperCase() : "";
      const box = new THREE.Box3().setFromObject(r.visuals);  // three.js world: y up
      const s = new THREE.Vector3((box.min.x + box.max.x) / 2, box.max.y,
                                  (box.min.z + box.max.z) / 2).project(viewer.camera);
      r.tag.style.display = s.z < 1 ? "" : "none";
      const half = r.tag.offsetWidth / 2;  // keep the tag inside the view
      r.tag.style.left = `${Math.min(Math.max(((s.x + 1) / 2) * width, half), width - half)}px`;
      r.tag.style.top = `${Math.max(((1 - s.y) / 2) * height - 6, r.tag.offsetHeight)}px`;
      r.items.forEach((item, i) => item.classList.toggle("playing", i === k));
      const cursor = r.plot && r.plot.querySelector(".cursor");
      if (cursor) {
        cursor.setAttribute("visibility", run ? "visible" : "hidden");
        if (run) {
          const d = r.plot.dataset;
          const x = +d.x0 + (+d.x1 - +d.x0) * Math.min(1, (t - run.start) / +d.t1);
          cursor.setAttribute("x1", x);
          cursor.setAttribute("x2", x);
          cursor.setAttribute("stroke", run.color);
        }
      }
    }
    requestAnimationFrame(follow);
  }
  follow();
})();
"""

#: Times (after the first) at which the scene's vertices are gathered to frame it.
FRAME_SAMPLES = 8
#: Distance of the camera as a multiple of the least that fits every vertex: the margin.
FRAME_MARGIN = 1.08
#: Width in pixels of a desired path's dot, at the distance the view is framed from.
DOT_PIXELS = 5.0
#: A dot is at most this fraction of the (median) spacing of its path's dots on screen, so
#: that most of the path followed shows between them.
DOT_GAP = 0.35
SCRIPT = (SCRIPT_TEMPLATE.replace("@SAMPLES@", str(FRAME_SAMPLES))
          .replace("@MARGIN@", repr(FRAME_MARGIN)).replace("@DOT@", repr(DOT_PIXELS))
          .replace("@GAP@", repr(DOT_GAP)))

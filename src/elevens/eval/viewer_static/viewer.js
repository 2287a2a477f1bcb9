// elevens replay viewer: plays replays (served as JSON by `elevens view`) on a <canvas>.
// No build step and no dependencies. World frame: metres, x to the right, y up, team 0 attacks
// +x; headings are radians from +x, counter-clockwise (the canvas flips y).
//
// For tests and scripting the page exposes its state as `window.viewerState` (read it) and a few
// actions as `window.viewerApi`; the canvas mirrors the frame and selection in data attributes.
"use strict";

(function () {
  const TEAM_COLOURS = ["rgb(40, 95, 235)", "rgb(225, 40, 40)"];
  const LEG_COLOURS = ["rgb(15, 40, 120)", "rgb(120, 15, 15)"];
  const SIGHT_COLOURS = ["rgb(150, 180, 255)", "rgb(255, 160, 160)"];
  const GRASS = ["rgb(58, 148, 58)", "rgb(66, 160, 66)"];
  const SURROUND = "rgb(38, 105, 42)";
  const LINE = "rgb(235, 235, 235)";
  const HEADING = "rgb(255, 225, 0)";
  const HIGHLIGHT = "rgb(255, 235, 60)";
  const FOV_FILL = "rgba(255, 255, 210, 0.22)";
  const STEPS_PER_SECOND = 20; // at 1x, as the GIFs and MP4s
  const TRAIL_STEPS = 25;
  const MARGIN = 4; // metres of surround around the lines
  const GOAL_DEPTH = 2.5;
  const PICK_TOLERANCE = 1.5; // metres beyond a player's radius that still select it

  const state = {
    ready: false,
    error: null,
    replays: [],
    replayIndex: null,
    numFrames: 0,
    frame: 0,
    step: 0,
    playing: false,
    speed: 1,
    trail: true,
    selected: null,
    visible: [],
    ballVisible: false,
    score: [0, 0],
    teamNames: ["", ""],
    goalFrames: [],
    framesDrawn: 0,
  };
  window.viewerState = state;

  const canvas = document.getElementById("pitch");
  const ctx = canvas.getContext("2d");
  const els = {
    select: document.getElementById("replay-select"),
    play: document.getElementById("play"),
    back: document.getElementById("step-back"),
    forward: document.getElementById("step-forward"),
    scrubber: document.getElementById("scrubber"),
    frameBox: document.getElementById("frame-box"),
    goalMarks: document.getElementById("goal-marks"),
    stage: document.getElementById("stage"),
    speed: document.getElementById("speed"),
    trail: document.getElementById("trail"),
    team0: document.getElementById("team0"),
    team1: document.getElementById("team1"),
    score: document.getElementById("score"),
    clock: document.getElementById("clock"),
    info: document.getElementById("info"),
  };

  let replay = null;
  let field = null; // {hl, hw, gh, radius, reach, ballRadius, fov, maxBallStep}
  let scale = 1; // device pixels per metre
  let lastTime = null;
  let progress = 0; // fractional steps accumulated while playing

  // ------------------------------------------------------------------ geometry
  function toCanvas(x, y) {
    return [(x + field.hl + MARGIN) * scale, (field.hw + MARGIN - y) * scale];
  }

  function clientToWorld(clientX, clientY) {
    const rect = canvas.getBoundingClientRect();
    const px = (clientX - rect.left) * (canvas.width / rect.width);
    const py = (clientY - rect.top) * (canvas.height / rect.height);
    return [px / scale - field.hl - MARGIN, field.hw + MARGIN - py / scale];
  }

  function worldToClient(x, y) {
    const rect = canvas.getBoundingClientRect();
    const [px, py] = toCanvas(x, y);
    return { x: rect.left + px * (rect.width / canvas.width),
             y: rect.top + py * (rect.height / canvas.height) };
  }

  function resize() {
    if (!field) return;
    const ratio = window.devicePixelRatio || 1;
    const worldWidth = 2 * field.hl + 2 * MARGIN;
    const worldHeight = 2 * field.hw + 2 * MARGIN;
    // The largest pitch that fits the stage's width and height (the window less the header,
    // controls and text), so nothing needs scrolling.
    const available = els.stage.getBoundingClientRect();
    const cssWidth = Math.max(
      200, Math.floor(Math.min(available.width, available.height * worldWidth / worldHeight)),
    );
    canvas.style.width = `${cssWidth}px`;
    canvas.width = Math.round(cssWidth * ratio);
    canvas.height = Math.round(canvas.width * worldHeight / worldWidth);
    scale = canvas.width / worldWidth;
    draw();
  }

  // ------------------------------------------------------------------ what a player sees
  // The env's rule (elevens.env.observe): an entity is visible if the direction to its centre is
  // within fov_half_angle of the heading (an entity on the player's centre counts as ahead).
  function sees(row, x, y, frame) {
    const p = replay.positions[frame][row];
    const h = replay.headings[frame][row];
    const dx = x - p[0];
    const dy = y - p[1];
    const d = Math.hypot(dx, dy);
    if (d <= 1e-6) return true;
    return (dx * Math.cos(h) + dy * Math.sin(h)) / d >= Math.cos(field.fov);
  }

  function updateVisibility() {
    state.visible = [];
    state.ballVisible = false;
    if (state.selected === null || !replay) return;
    const players = replay.positions[state.frame];
    for (let j = 0; j < players.length; j++) {
      if (j !== state.selected && sees(state.selected, players[j][0], players[j][1], state.frame)) {
        state.visible.push(j);
      }
    }
    const ball = replay.ball_position[state.frame];
    state.ballVisible = sees(state.selected, ball[0], ball[1], state.frame);
  }

  // ------------------------------------------------------------------ drawing
  function drawPitch() {
    const { hl, hw, gh } = field;
    ctx.fillStyle = SURROUND;
    ctx.fillRect(0, 0, canvas.width, canvas.height);
    const stripes = 10;
    for (let i = 0; i < stripes; i++) {
      const x0 = -hl + (i * 2 * hl) / stripes;
      const [left, top] = toCanvas(x0, hw);
      const [right, bottom] = toCanvas(x0 + (2 * hl) / stripes, -hw);
      ctx.fillStyle = GRASS[i % 2];
      ctx.fillRect(left, top, right - left, bottom - top);
    }
    ctx.strokeStyle = LINE;
    ctx.lineWidth = Math.max(1, 0.3 * scale);
    for (const [side, colour] of [[-1, TEAM_COLOURS[0]], [1, TEAM_COLOURS[1]]]) {
      const [xa, top] = toCanvas(side * hl, gh);
      const [xb, bottom] = toCanvas(side * (hl + GOAL_DEPTH), -gh);
      ctx.fillStyle = colour;
      ctx.globalAlpha = 0.45;
      ctx.fillRect(Math.min(xa, xb), top, Math.abs(xb - xa), bottom - top);
      ctx.globalAlpha = 1;
      ctx.strokeRect(Math.min(xa, xb), top, Math.abs(xb - xa), bottom - top);
    }
    const [left, top] = toCanvas(-hl, hw);
    const [right, bottom] = toCanvas(hl, -hw);
    ctx.strokeRect(left, top, right - left, bottom - top);
    const [cx, cy] = toCanvas(0, 0);
    ctx.beginPath();
    ctx.moveTo(cx, top);
    ctx.lineTo(cx, bottom);
    ctx.stroke();
    ctx.beginPath();
    ctx.arc(cx, cy, 0.0915 * 2 * hl * scale, 0, 2 * Math.PI);
    ctx.stroke();
  }

  function drawFieldOfView(frame) {
    const row = state.selected;
    const p = replay.positions[frame][row];
    const h = replay.headings[frame][row];
    const [px, py] = toCanvas(p[0], p[1]);
    const reach = 2 * Math.hypot(field.hl, field.hw) * scale;
    ctx.save();
    const [left, top] = toCanvas(-field.hl, field.hw);
    const [right, bottom] = toCanvas(field.hl, -field.hw);
    ctx.beginPath();
    ctx.rect(left, top, right - left, bottom - top);
    ctx.clip();
    ctx.beginPath();
    ctx.moveTo(px, py);
    // The canvas's y points down, so world angles are negated.
    ctx.arc(px, py, reach, -(h + field.fov), -(h - field.fov), false);
    ctx.closePath();
    ctx.fillStyle = FOV_FILL;
    ctx.fill();
    ctx.restore();
    const n = replay.players_per_team;
    ctx.lineWidth = Math.max(1, 0.3 * scale);
    for (const j of state.visible) {
      const q = replay.positions[frame][j];
      ctx.strokeStyle = SIGHT_COLOURS[Math.floor(j / n)];
      line(p, q);
    }
    if (state.ballVisible) {
      ctx.strokeStyle = "rgb(255, 255, 255)";
      line(p, replay.ball_position[frame]);
    }
  }

  function line(a, b) {
    const [ax, ay] = toCanvas(a[0], a[1]);
    const [bx, by] = toCanvas(b[0], b[1]);
    ctx.beginPath();
    ctx.moveTo(ax, ay);
    ctx.lineTo(bx, by);
    ctx.stroke();
  }

  function disc(x, y, radius, fill, stroke) {
    const [cx, cy] = toCanvas(x, y);
    ctx.beginPath();
    ctx.arc(cx, cy, radius * scale, 0, 2 * Math.PI);
    if (fill) { ctx.fillStyle = fill; ctx.fill(); }
    if (stroke) { ctx.strokeStyle = stroke; ctx.stroke(); }
  }

  function drawPlayers(frame) {
    const n = replay.players_per_team;
    const positions = replay.positions[frame];
    const headings = replay.headings[frame];
    const dim = state.selected !== null;
    const seen = new Set(state.visible);
    for (let row = 0; row < positions.length; row++) {
      const team = Math.floor(row / n);
      const [x, y] = positions[row];
      const h = headings[row];
      const fx = Math.cos(h);
      const fy = Math.sin(h);
      ctx.globalAlpha = dim && row !== state.selected && !seen.has(row) ? 0.4 : 1;
      ctx.lineCap = "round";
      ctx.lineWidth = Math.max(1, 0.45 * scale);
      ctx.strokeStyle = LEG_COLOURS[team];
      line([x + field.reach * fy, y - field.reach * fx], [x - field.reach * fy, y + field.reach * fx]);
      ctx.lineWidth = Math.max(1, 0.15 * scale);
      disc(x, y, field.radius, TEAM_COLOURS[team], "rgb(20, 20, 20)");
      ctx.lineWidth = Math.max(1, 0.35 * scale);
      ctx.strokeStyle = HEADING;
      line([x, y], [x + 1.9 * field.radius * fx, y + 1.9 * field.radius * fy]);
      ctx.lineCap = "butt";
    }
    // Shirt numbers 1..n per team, above and to the right of each player, on top of all bodies.
    const size = Math.max(10, Math.round(1.7 * scale));
    ctx.font = `bold ${size}px sans-serif`;
    ctx.textAlign = "left";
    ctx.textBaseline = "bottom";
    ctx.lineJoin = "round";
    for (let row = 0; row < positions.length; row++) {
      const [x, y] = positions[row];
      const [cx, cy] = toCanvas(x + 0.7 * field.radius, y + 0.7 * field.radius);
      ctx.globalAlpha = dim && row !== state.selected && !seen.has(row) ? 0.4 : 1;
      ctx.lineWidth = Math.max(2, size / 5);
      ctx.strokeStyle = LEG_COLOURS[Math.floor(row / n)];
      ctx.strokeText(String((row % n) + 1), cx, cy);
      ctx.fillStyle = "rgb(255, 255, 255)";
      ctx.fillText(String((row % n) + 1), cx, cy);
    }
    ctx.globalAlpha = 1;
    if (state.selected !== null) {
      const [x, y] = positions[state.selected];
      ctx.lineWidth = Math.max(1.5, 0.3 * scale);
      disc(x, y, field.radius + 0.9, null, HIGHLIGHT);
    }
  }

  function drawBall(frame) {
    if (state.trail) {
      const first = Math.max(0, frame - TRAIL_STEPS);
      for (let t = first; t < frame; t++) {
        const [ax, ay] = replay.ball_position[t];
        const [bx, by] = replay.ball_position[t + 1];
        // A jump faster than the ball can move is a respawn after a goal: no trail across it.
        if (Math.hypot(bx - ax, by - ay) > field.maxBallStep) continue;
        const age = (frame - t) / TRAIL_STEPS;
        ctx.strokeStyle = `rgba(255, 255, 255, ${0.75 * (1 - age)})`;
        ctx.lineWidth = Math.max(1, 0.5 * scale * (1 - age));
        line(replay.ball_position[t], replay.ball_position[t + 1]);
      }
    }
    const [x, y] = replay.ball_position[frame];
    ctx.globalAlpha = state.selected !== null && !state.ballVisible ? 0.45 : 1;
    ctx.lineWidth = Math.max(1, 0.15 * scale);
    disc(x, y, field.ballRadius, "rgb(255, 255, 255)", "rgb(20, 20, 20)");
    ctx.globalAlpha = 1;
  }

  function draw() {
    if (!replay || !field) return;
    const frame = state.frame;
    updateVisibility();
    drawPitch();
    if (state.selected !== null) drawFieldOfView(frame);
    drawPlayers(frame);
    drawBall(frame);
    state.framesDrawn += 1;
    updateLabels();
  }

  function updateLabels() {
    const last = state.frame === state.numFrames - 1;
    state.step = replay.step[state.frame];
    // The last recorded entry is the state before the last step; the final score includes it.
    state.score = last ? replay.final_score.slice() : replay.score[state.frame].slice();
    els.score.textContent = `${state.score[0]} : ${state.score[1]}`;
    els.clock.textContent = last
      ? `full time (${replay.steps} steps)`
      : `step ${state.step} / ${replay.steps}`;
    els.scrubber.value = String(state.frame);
    if (document.activeElement !== els.frameBox) els.frameBox.value = String(state.frame);
    els.play.textContent = state.playing ? "❚❚ pause" : "▶ play";
    canvas.dataset.frame = String(state.frame);
    canvas.dataset.selected = state.selected === null ? "" : String(state.selected);
    if (state.selected === null) {
      els.info.textContent = "Click a player to select it and see its field of view. " +
        "Space plays and pauses; the arrow keys step; Home and End go to the ends.";
    } else {
      const n = replay.players_per_team;
      const team = Math.floor(state.selected / n);
      const mates = state.visible.filter((j) => Math.floor(j / n) === team).length;
      const opponents = state.visible.length - mates;
      els.info.textContent = `Selected: ${replay.team_names[team]} (team ${team}) player ` +
        `${state.selected % n} (row ${state.selected}). It sees ${mates} teammate(s), ` +
        `${opponents} opponent(s) and ${state.ballVisible ? "the ball" : "not the ball"}. ` +
        "Click it again or on the grass to deselect.";
    }
  }

  // ------------------------------------------------------------------ playback
  function seek(frame) {
    if (!replay) return;
    state.frame = Math.max(0, Math.min(state.numFrames - 1, Math.round(frame)));
    draw();
  }

  function play() {
    if (!replay) return;
    if (state.frame >= state.numFrames - 1) seek(0);
    state.playing = true;
    lastTime = null;
    progress = 0;
    updateLabels();
  }

  function pause() {
    state.playing = false;
    if (replay) updateLabels();
  }

  function tick(now) {
    if (state.playing && replay) {
      if (lastTime !== null) {
        // Cap a long gap (a background tab) at a quarter second of play.
        progress += Math.min(now - lastTime, 250) / 1000 * STEPS_PER_SECOND * state.speed;
      }
      lastTime = now;
      const whole = Math.floor(progress);
      if (whole > 0) {
        progress -= whole;
        const next = state.frame + whole;
        if (next >= state.numFrames - 1) {
          state.frame = state.numFrames - 1;
          state.playing = false;
        } else {
          state.frame = next;
        }
        draw();
      }
    } else {
      lastTime = null;
    }
    schedule();
  }

  function schedule() {
    // requestAnimationFrame stops in hidden tabs; a timer keeps the clock honest there.
    if (document.hidden) setTimeout(() => tick(performance.now()), 50);
    else requestAnimationFrame(tick);
  }

  function select(row) {
    if (!replay) return;
    const count = replay.positions[state.frame].length;
    state.selected = row === null || row === undefined || row < 0 || row >= count ? null : row;
    draw();
  }

  function pick(clientX, clientY) {
    const [x, y] = clientToWorld(clientX, clientY);
    const players = replay.positions[state.frame];
    let best = null;
    let bestDistance = field.radius + PICK_TOLERANCE;
    for (let row = 0; row < players.length; row++) {
      const d = Math.hypot(players[row][0] - x, players[row][1] - y);
      if (d <= bestDistance) { best = row; bestDistance = d; }
    }
    return best;
  }

  // ------------------------------------------------------------------ loading
  async function fetchJson(url) {
    const response = await fetch(url, { cache: "no-store" });
    if (!response.ok) throw new Error(`${url}: HTTP ${response.status}`);
    return response.json();
  }

  async function loadReplay(index) {
    state.ready = false;
    pause();
    replay = await fetchJson(`replays/${index}.json`);
    const p = replay.params;
    field = {
      hl: p.field_length / 2,
      hw: p.field_width / 2,
      gh: p.goal_width / 2,
      radius: p.player_radius,
      reach: p.leg_reach,
      ballRadius: p.ball_radius,
      fov: p.fov_half_angle,
      maxBallStep: p.ball_max_speed + 1, // the speed cap per step, and some slack
    };
    state.replayIndex = index;
    state.numFrames = replay.positions.length;
    state.teamNames = replay.team_names.slice();
    state.selected = null;
    els.team0.textContent = replay.team_names[0];
    els.team1.textContent = replay.team_names[1];
    els.scrubber.max = String(state.numFrames - 1);
    els.frameBox.max = String(state.numFrames - 1);
    markGoals();
    els.select.value = String(index);
    state.frame = 0;
    resize();
    state.ready = true;
    play();
  }

  function markGoals() {
    // A mark under the timeline at each frame whose score differs from the frame before, in
    // the scoring team's colour; the final score counts for a goal in the last step.
    els.goalMarks.replaceChildren();
    state.goalFrames = [];
    const last = state.numFrames - 1;
    for (let frame = 1; frame <= last + 1; frame++) {
      const before = replay.score[frame - 1];
      const after = frame <= last ? replay.score[frame] : replay.final_score;
      for (const team of [0, 1]) {
        if (after[team] > before[team]) {
          const at = Math.min(frame, last);
          state.goalFrames.push({ frame: at, team });
          const mark = document.createElement("span");
          mark.className = `team${team}`;
          mark.style.left = `${(100 * at) / Math.max(1, last)}%`;
          mark.title = `${replay.team_names[team]} scores (frame ${at})`;
          els.goalMarks.appendChild(mark);
        }
      }
    }
  }

  async function start() {
    try {
      const index = await fetchJson("replays/index.json");
      state.replays = index.replays;
      for (const item of index.replays) {
        const option = document.createElement("option");
        option.value = String(item.index);
        option.textContent = `${item.index}: ${item.team_names[0]} ${item.final_score[0]} : ` +
          `${item.final_score[1]} ${item.team_names[1]} (${item.name})`;
        els.select.appendChild(option);
      }
      if (index.replays.length === 0) {
        els.info.textContent = "No replays: start the viewer with replay files " +
          "(elevens view game.npz ...).";
        state.ready = true;
        return;
      }
      const wanted = Number(new URLSearchParams(location.hash.slice(1)).get("replay") || 0);
      await loadReplay(wanted >= 0 && wanted < index.replays.length ? wanted : 0);
    } catch (error) {
      state.error = String(error);
      els.info.textContent = `Could not load replays: ${error}`;
    }
  }

  // ------------------------------------------------------------------ events
  els.play.addEventListener("click", () => (state.playing ? pause() : play()));
  els.back.addEventListener("click", () => { pause(); seek(state.frame - 1); });
  els.forward.addEventListener("click", () => { pause(); seek(state.frame + 1); });
  // Dragging the scrubber pauses; letting go hands the keyboard back to the page.
  els.scrubber.addEventListener("input", () => {
    const frame = Number(els.scrubber.value); // read first: pause() redraws the old frame
    pause();
    seek(frame);
  });
  els.scrubber.addEventListener("change", () => els.scrubber.blur());
  els.scrubber.addEventListener("pointerup", () => els.scrubber.blur());
  els.frameBox.addEventListener("change", () => {
    const frame = Number(els.frameBox.value);
    pause();
    seek(frame);
    els.frameBox.blur();
  });
  els.speed.addEventListener("change", () => { state.speed = Number(els.speed.value); });
  els.trail.addEventListener("change", () => { state.trail = els.trail.checked; draw(); });
  els.select.addEventListener("change", () => {
    loadReplay(Number(els.select.value)).catch((error) => {
      state.error = String(error);
      els.info.textContent = `Could not load the replay: ${error}`;
    });
  });
  canvas.addEventListener("click", (event) => {
    if (!replay) return;
    const row = pick(event.clientX, event.clientY);
    select(row === state.selected ? null : row);
  });
  window.addEventListener("keydown", (event) => {
    if (event.target instanceof HTMLInputElement || event.target instanceof HTMLSelectElement) {
      return;
    }
    if (event.code === "Space") { event.preventDefault(); state.playing ? pause() : play(); }
    if (event.code === "ArrowLeft") { pause(); seek(state.frame - 1); }
    if (event.code === "ArrowRight") { pause(); seek(state.frame + 1); }
    if (event.code === "Home") { event.preventDefault(); pause(); seek(0); }
    if (event.code === "End") { event.preventDefault(); pause(); seek(state.numFrames - 1); }
  });
  window.addEventListener("resize", resize);

  window.viewerApi = {
    play,
    pause,
    seek,
    select,
    loadReplay,
    worldToClient,
    playerClientPosition(row) {
      const p = replay.positions[state.frame][row];
      return worldToClient(p[0], p[1]);
    },
  };

  schedule();
  start();
})();

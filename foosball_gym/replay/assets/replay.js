"use strict";
// The replay page: unpacks the frames written by foosball_gym.replay.page and draws the table
// from above, as the simulator's rgb_array frames show it. window.replay lets a test (or a
// curious student) ask where things are drawn.
(function () {
  const data = JSON.parse(document.getElementById("replay-data").textContent);
  const $ = (id) => document.getElementById(id);
  const canvas = $("table");
  const ctx = canvas.getContext("2d");
  const T = data.table;
  // The drawing spans the table's outer walls and goal pockets, nothing else.
  const X = T.pocket_back_x + T.wall;
  const Y = T.field_half_width + T.wall;
  const HOLD_S = 0.6; // a finished episode stays on the screen this long when playing on
  // The track shown unless "whole track" is asked for: a long match's whole track is a tangle.
  const TRAIL_S = 2.0;
  const TRACK_STYLE = {
    ball: { colour: "#ff8c00", label: "true ball (the simulator's)" },
    estimate: { colour: "#1565ff", label: "estimate the policy saw (camera + Kalman filter)" },
    measured: { colour: "#d000c8", label: "camera detection" },
  };

  const state = {
    episode: 0, frame: 0, playing: false, speed: 1, playhead: 0, hold: 0, trackFrom: 0,
  };
  let values = null; // channel name -> Float64Array over all frames
  let scale = 1; // canvas pixels per metre
  let lastTick = null;

  function rgb(c) {
    return `rgb(${Math.round(255 * c[0])}, ${Math.round(255 * c[1])}, ${Math.round(255 * c[2])})`;
  }
  const COLOUR = {};
  for (const [name, c] of Object.entries(data.colours)) COLOUR[name] = rgb(c);

  async function inflate(b64) {
    const bytes = Uint8Array.from(atob(b64), (c) => c.charCodeAt(0));
    const stream = new Blob([bytes]).stream().pipeThrough(new DecompressionStream("deflate"));
    const buffer = await new Response(stream).arrayBuffer();
    const view = new DataView(buffer);
    const ints = new Int32Array(buffer.byteLength / 4);
    for (let i = 0; i < ints.length; i++) ints[i] = view.getInt32(4 * i, true);
    return ints;
  }

  function unpack(ints) {
    const n = data.frames;
    const out = {};
    data.channels.forEach((ch, k) => {
      const column = new Float64Array(n);
      let v = 0;
      for (let i = 0; i < n; i++) {
        v += ints[k * n + i];
        column[i] = v === data.missing ? NaN : v * ch.unit;
      }
      out[ch.name] = column;
    });
    return out;
  }

  // ------------------------------------------------------------------ geometry

  function toPixel(x, y) {
    return [(x + X) * scale, (Y - y) * scale];
  }

  function rect(x0, y0, x1, y1, fill) {
    const [px0, py0] = toPixel(Math.min(x0, x1), Math.max(y0, y1));
    const [px1, py1] = toPixel(Math.max(x0, x1), Math.min(y0, y1));
    ctx.fillStyle = fill;
    ctx.fillRect(px0, py0, px1 - px0, py1 - py0);
  }

  function resize() {
    const width = canvas.parentElement.clientWidth || 960;
    const ratio = window.devicePixelRatio || 1;
    canvas.width = Math.round(width * ratio);
    canvas.height = Math.round((width * Y) / X * ratio);
    canvas.style.height = `${canvas.height / ratio}px`;
    scale = canvas.width / (2 * X);
  }

  // ------------------------------------------------------------------ drawing

  function drawTable() {
    const lx = T.field_half_length, ly = T.field_half_width, w = T.wall;
    const gw = T.goal_half_width, endOut = T.field_half_length + T.end_wall;
    ctx.fillStyle = "#d9d9d6";
    ctx.fillRect(0, 0, canvas.width, canvas.height);
    for (const s of [-1, 1]) {
      rect(-X, s * ly, X, s * (ly + w), COLOUR.wall); // side walls
      rect(s * lx, gw, s * endOut, ly, COLOUR.wall); // end walls beside the goal
      rect(s * lx, -gw, s * endOut, -ly, COLOUR.wall);
      rect(s * endOut, -(gw + w), s * X, gw + w, COLOUR.pocket); // the goal's pocket
      rect(s * lx, -gw, s * endOut, gw, COLOUR.pocket); // its mouth
    }
    rect(-lx, -ly, lx, ly, COLOUR.field);
  }

  function value(name, i) {
    const column = values[name];
    return column ? column[i] : NaN;
  }

  function drawRods(i) {
    const [fx, fy] = T.figurine_size;
    for (const rod of data.rods) {
      const [px] = toPixel(rod.x, 0);
      ctx.fillStyle = COLOUR.rod;
      ctx.fillRect(px - T.rod_radius * scale, 0, 2 * T.rod_radius * scale, canvas.height);
      const slide = value(`${rod.name}.slide`, i);
      if (Number.isNaN(slide)) continue;
      const spinKnown = !Number.isNaN(value(`${rod.name}.spin`, i));
      const spin = spinKnown ? value(`${rod.name}.spin`, i) : 0;
      const s = Math.sin(spin), c = Math.abs(Math.cos(spin));
      // Seen from above a turned figurine stretches from its head to its foot.
      const foot = rod.x + rod.direction * T.figurine_foot_below_axis * s;
      const head = rod.x - rod.direction * T.figurine_head_above_axis * s;
      const x0 = Math.min(foot, head, rod.x) - (fx / 2) * c;
      const x1 = Math.max(foot, head, rod.x) + (fx / 2) * c;
      for (const offset of rod.offsets) {
        const y = rod.direction * (slide + offset);
        rect(x0, y - fy / 2, x1, y + fy / 2, COLOUR[rod.team]);
        const [qx0, qy0] = toPixel(x0, y + fy / 2);
        const [qx1, qy1] = toPixel(x1, y - fy / 2);
        ctx.lineWidth = Math.max(1, 0.002 * scale);
        ctx.strokeStyle = rod.team === "home" ? "#555" : "#000";
        if (!spinKnown) ctx.setLineDash([3, 3]);
        ctx.strokeRect(qx0, qy0, qx1 - qx0, qy1 - qy0);
        ctx.setLineDash([]);
        if (Math.abs(s) > 0.05) {
          // The foot, so that a kick shows which way it goes.
          const [px1, py1] = toPixel(foot, y);
          ctx.fillStyle = rod.team === "home" ? "#9a9a9a" : "#555";
          ctx.beginPath();
          ctx.arc(px1, py1, Math.max(2, 0.006 * scale), 0, 2 * Math.PI);
          ctx.fill();
        }
      }
    }
  }

  function drawTrack(name, from, to) {
    const style = TRACK_STYLE[name];
    ctx.strokeStyle = style.colour;
    ctx.fillStyle = style.colour;
    if (name === "measured") {
      for (let i = from; i <= to; i++) {
        const x = value("measured.x", i), y = value("measured.y", i);
        if (Number.isNaN(x) || Number.isNaN(y)) continue;
        const [px, py] = toPixel(x, y);
        ctx.fillRect(px - 1.5, py - 1.5, 3, 3);
      }
      return;
    }
    ctx.lineWidth = Math.max(1.5, 0.003 * scale);
    ctx.beginPath();
    let pen = false;
    for (let i = from; i <= to; i++) {
      const x = value(`${name}.x`, i), y = value(`${name}.y`, i);
      if (Number.isNaN(x) || Number.isNaN(y)) { pen = false; continue; }
      const [px, py] = toPixel(x, y);
      if (pen) ctx.lineTo(px, py); else ctx.moveTo(px, py);
      pen = true;
    }
    ctx.stroke();
  }

  function drawBalls(i) {
    const r = Math.max(3, T.ball_radius * scale);
    for (const name of data.tracks) {
      const x = value(`${name}.x`, i), y = value(`${name}.y`, i);
      if (Number.isNaN(x) || Number.isNaN(y)) continue;
      const [px, py] = toPixel(x, y);
      ctx.beginPath();
      if (name === "ball") {
        ctx.arc(px, py, r, 0, 2 * Math.PI);
        ctx.fillStyle = COLOUR.ball;
        ctx.fill();
        ctx.lineWidth = 1;
        ctx.strokeStyle = "#7a3d00";
        ctx.stroke();
      } else if (name === "estimate") {
        ctx.arc(px, py, r, 0, 2 * Math.PI);
        ctx.lineWidth = Math.max(2, 0.004 * scale);
        ctx.strokeStyle = TRACK_STYLE.estimate.colour;
        ctx.stroke();
      } else {
        const d = 0.7 * r;
        ctx.lineWidth = 2;
        ctx.strokeStyle = TRACK_STYLE.measured.colour;
        ctx.moveTo(px - d, py - d); ctx.lineTo(px + d, py + d);
        ctx.moveTo(px - d, py + d); ctx.lineTo(px + d, py - d);
        ctx.stroke();
      }
    }
  }

  function draw() {
    if (!values) return;
    const episode = data.episodes[state.episode];
    const i = episode.start + state.frame;
    drawTable();
    let from = episode.start;
    if (!$("whole-track").checked) {
      const t = values.t;
      while (from < i && t[i] - t[from] > TRAIL_S) from++;
    }
    state.trackFrom = from - episode.start;
    for (const name of ["measured", "estimate", "ball"]) {
      if (data.tracks.includes(name)) drawTrack(name, from, i);
    }
    drawRods(i);
    drawBalls(i);
    showStatus(episode, i);
  }

  function showStatus(episode, i) {
    const t0 = values.t[episode.start];
    $("episode-label").textContent =
      `${episode.label} (${state.episode + 1} of ${data.episodes.length})`;
    $("clock").textContent =
      `t = ${(values.t[i] - t0).toFixed(2)} s, frame ${state.frame + 1} of ${episode.frames}`;
    const passed = episode.events.filter(([frame]) => frame <= state.frame);
    $("event").textContent = passed.length ? passed[passed.length - 1][1] : "";
    $("outcome").textContent = episode.outcome ? `ended: ${episode.outcome}` : "";
    $("time").value = String(state.frame);
  }

  // ------------------------------------------------------------------ moving through it

  function seek(episode, frame) {
    const e = Math.max(0, Math.min(data.episodes.length - 1, episode));
    state.episode = e;
    $("episode").value = String(e);
    $("time").max = String(data.episodes[e].frames - 1);
    const ep = data.episodes[e];
    state.frame = Math.max(0, Math.min(ep.frames - 1, frame));
    state.playhead = values.t[ep.start + state.frame] - values.t[ep.start];
    state.hold = 0;
    draw();
  }

  function setPlaying(on) {
    state.playing = on;
    $("play").textContent = on ? "Pause" : "Play";
    lastTick = null;
    if (on) requestAnimationFrame(tick);
  }

  function tick(now) {
    if (!state.playing) return;
    const dt = lastTick === null ? 0 : (now - lastTick) / 1000;
    lastTick = now;
    const ep = data.episodes[state.episode];
    const t = values.t;
    const last = ep.start + ep.frames - 1;
    if (state.frame >= ep.frames - 1) {
      state.hold += dt;
      if (state.hold >= HOLD_S) {
        if (state.episode + 1 < data.episodes.length) seek(state.episode + 1, 0);
        else { setPlaying(false); return; }
      }
    } else {
      state.playhead += dt * state.speed;
      let i = ep.start + state.frame;
      while (i < last && t[i + 1] - t[ep.start] <= state.playhead) i++;
      if (i !== ep.start + state.frame) {
        state.frame = i - ep.start;
        draw();
      }
    }
    requestAnimationFrame(tick);
  }

  function wire() {
    const select = $("episode");
    data.episodes.forEach((ep, k) => {
      const option = document.createElement("option");
      option.value = String(k);
      option.textContent = ep.outcome ? `${ep.label}: ${ep.outcome}` : ep.label;
      select.appendChild(option);
    });
    select.addEventListener("change", () => seek(Number(select.value), 0));
    $("time").addEventListener("input", (ev) => {
      seek(state.episode, Number(ev.target.value));
    });
    $("play").addEventListener("click", () => {
      const ep = data.episodes[state.episode];
      const atEnd = state.frame >= ep.frames - 1 && state.episode === data.episodes.length - 1;
      if (!state.playing && atEnd) seek(state.episode, 0);
      setPlaying(!state.playing);
    });
    $("speed").addEventListener("change", (ev) => { state.speed = Number(ev.target.value); });
    $("prev-frame").addEventListener("click", () => seek(state.episode, state.frame - 1));
    $("next-frame").addEventListener("click", () => seek(state.episode, state.frame + 1));
    $("prev-episode").addEventListener("click", () => seek(state.episode - 1, 0));
    $("next-episode").addEventListener("click", () => seek(state.episode + 1, 0));
    $("whole-track").addEventListener("change", draw);
    document.addEventListener("keydown", (ev) => {
      if (ev.target instanceof HTMLSelectElement || ev.target instanceof HTMLInputElement &&
          ev.target.type !== "range" && ev.target.type !== "checkbox") return;
      const moves = {
        ArrowLeft: () => seek(state.episode, state.frame - 1),
        ArrowRight: () => seek(state.episode, state.frame + 1),
        PageUp: () => seek(state.episode - 1, 0),
        PageDown: () => seek(state.episode + 1, 0),
        " ": () => $("play").click(),
      };
      const move = moves[ev.key];
      if (move) { ev.preventDefault(); move(); }
    });
    window.addEventListener("resize", () => { resize(); draw(); });
    const legend = $("legend");
    const items = data.tracks.map((name) => [TRACK_STYLE[name].colour, TRACK_STYLE[name].label]);
    items.push([COLOUR.home, "home side (the policy)"], [COLOUR.away, "away side"]);
    for (const [colour, text] of items) {
      const li = document.createElement("li");
      const swatch = document.createElement("span");
      swatch.className = "swatch";
      swatch.style.background = colour;
      li.append(swatch, text);
      legend.appendChild(li);
    }
    $("notes").textContent = data.notes.join("\n");
  }

  async function start() {
    wire();
    resize();
    if (typeof DecompressionStream === "undefined") {
      throw new Error("this browser cannot unpack the replay (no DecompressionStream); " +
                      "open the page in a current Chrome, Firefox, Safari or Edge");
    }
    values = unpack(await inflate(data.data));
    seek(0, 0);
    document.body.dataset.ready = "true";
  }

  const ready = start().catch((err) => {
    const box = $("error");
    box.hidden = false;
    box.textContent = String(err.message || err);
    document.body.dataset.ready = "failed";
  });

  window.replay = {
    ready,
    seek,
    toPixel: (x, y) => {
      const ratio = canvas.width / canvas.getBoundingClientRect().width;
      const [px, py] = toPixel(x, y);
      const box = canvas.getBoundingClientRect();
      return [box.left + px / ratio, box.top + py / ratio];
    },
    // A channel's value ("ball.x", "home_keeper.spin", "t") at the frame shown.
    value: (name) => value(name, data.episodes[state.episode].start + state.frame),
    get episode() { return state.episode; },
    get frame() { return state.frame; },
    // The episode's frame the tracks are drawn from.
    get trackFrom() { return state.trackFrom; },
    get playing() { return state.playing; },
    get speed() { return state.speed; },
  };
})();

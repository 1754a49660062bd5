// The campaign page: renders the state pushed by /campaigns/ID/stream (server-sent events).
// Every stored string is set as text (textContent), never as markup.
"use strict";
(function () {
  const initial = JSON.parse(document.getElementById("initial").textContent);
  const $ = (id) => document.getElementById(id);
  const num = (v, digits) => (v === null || v === undefined ? "" : v.toFixed(digits));
  const hms = (s) => {
    if (s === null || s === undefined) return "?";
    s = Math.max(0, Math.round(s));
    const h = Math.floor(s / 3600), m = Math.floor((s % 3600) / 60), r = s % 60;
    return h + ":" + String(m).padStart(2, "0") + ":" + String(r).padStart(2, "0");
  };
  window.stationUpdates = 0;

  function row(tbody, cells, cls) {
    const tr = document.createElement("tr");
    if (cls) tr.className = cls;
    for (const c of cells) {
      const td = document.createElement("td");
      td.textContent = c === null || c === undefined ? "" : String(c);
      tr.appendChild(td);
    }
    tbody.appendChild(tr);
  }

  function trace(points, id = "trace") {
    const svg = $(id);
    svg.replaceChildren();
    $(id + "-points").textContent = String(points.length);
    if (!points.length) return;
    const ns = "http://www.w3.org/2000/svg", W = 600, H = 220, pad = 30;
    const xs = points.map((p) => p[0]), ys = points.map((p) => p[1]);
    const x0 = Math.min(...xs), x1 = Math.max(...xs), y0 = Math.min(...ys), y1 = Math.max(...ys);
    const sx = (x) => pad + ((x - x0) / (x1 - x0 || 1)) * (W - 2 * pad);
    const sy = (y) => H - pad - ((y - y0) / (y1 - y0 || 1)) * (H - 2 * pad);
    const line = document.createElementNS(ns, "polyline");
    line.setAttribute("points", points.map((p) => sx(p[0]).toFixed(1) + "," + sy(p[1]).toFixed(1)).join(" "));
    svg.appendChild(line);
    for (const [x, y, t] of [[2, 12, y1.toFixed(4) + "°"], [2, H - pad + 4, y0.toFixed(4) + "°"],
                             [pad, H - 6, hms(x0)], [W - pad - 40, H - 6, hms(x1)]]) {
      const label = document.createElementNS(ns, "text");
      label.setAttribute("x", x); label.setAttribute("y", y); label.textContent = t;
      svg.appendChild(label);
    }
  }

  const series = (j) => "j=" + j + (j === 1 ? " (before rocking)" : " (rocking)");
  let pace = null;  // [stand ms, wall s] of the first live snapshot of this page

  const WAITING = "waiting for the operator";  // the engine's phase while a prompt is open
  const ROCKING = ["confirming the stand rocks as commanded", "settling", "observing"];

  // The running acquisition's own snapshot (between the database's writes). While it waits
  // for the operator its series has ended: the stored state (render) tells where it goes on.
  function live(l, counted) {
    if (counted) window.stationUpdates += 1;
    if (l.trial === 0 || l.phase === WAITING) return;
    $("trial").textContent = l.trial + "/" + l.n_trials;
    $("series").textContent = series(l.j);
    $("observation").textContent = l.k + "/" + l.n_obs;
    $("phase").textContent = l.phase + (l.j === 2 && ROCKING.includes(l.phase) ? ", rocking" : "");
    const v = l.values_deg;
    if (v.length) {
      const mean = v.reduce((a, b) => a + b, 0) / v.length;
      const sd = v.length > 1 ? Math.sqrt(v.reduce((a, b) => a + (b - mean) ** 2, 0) / (v.length - 1)) : null;
      $("mean").textContent = num(mean, 4) + "°" + (sd === null ? "" : " (s = " + num(sd, 4) + "°)");
    }
    if (l.settle_spread_deg !== null) $("settle").textContent = "window means within ±" + num(l.settle_spread_deg, 4) + "°";
    $("stand-time").textContent = hms(l.now_ms / 1000);
    $("heading-figure").hidden = false;
    trace(l.heading_trace, "heading");
    if (pace === null || l.now_ms < pace[0]) pace = [l.now_ms, l.wall_time];
    const rate = (l.now_ms - pace[0]) / 1000 / (l.wall_time - pace[1]);
    $("eta").textContent = "stand " + hms(l.remaining_ms / 1000) + ", wall " + (rate > 0 ? hms(l.remaining_ms / 1000 / rate) : "?");
  }

  // The question the acquisition waits for, in a modal dialog: a text field, or "yes" to
  // confirm.
  function prompt(p) {
    const dialog = $("prompt");
    if (!p) {
      if (dialog.open) dialog.close();
      return;
    }
    if (!dialog.open) dialog.showModal();
    if ($("prompt-id").value === p.id) return;
    $("prompt-id").value = p.id;
    $("prompt-text").textContent = p.text;
    const confirm = p.kind === "confirm";
    $("prompt-answer").type = confirm ? "hidden" : "text";
    $("prompt-answer").value = confirm ? "yes" : "";
    $("answer").textContent = confirm ? "yes, confirm" : "answer";
  }

  const yesNo = (v) => (v === null || v === undefined ? "not tested" : v ? "yes" : "no");
  const estimate = (e, scale, digits, unit) =>
    e === null ? "not estimated" : num(e.value / scale, digits) + " (" +
      num(e.low / scale, digits) + " to " + num(e.high / scale, digits) + ")" + unit;

  // The status banner: what the database holds (and whether the run waits for the operator).
  function banner(s) {
    const status = s.prompt ? "waiting for the operator" : s.status;
    $("banner").className = "banner status-" + (s.prompt ? "waiting" : s.status);
    $("status").textContent = status;
    let detail = s.reason || "";
    if (s.status === "interrupted") detail = "its process ended without finishing: resume continues it";
    if (s.prompt) detail = "the stand is stopped until the question is answered";
    if (s.status === "completed") detail = s.result ? s.result.verdict : "not analysed yet: generate the report";
    $("status-detail").textContent = detail;
    $("progress").max = Math.max(1, s.observations_planned);
    $("progress").value = s.observations;
    $("progress-text").textContent = s.observations + "/" + s.observations_planned + " observations";
  }

  // The latest analysis run's result and the report's decision; the campaign's report files.
  function result(s) {
    const r = s.result;
    $("result").hidden = !r;
    if (r) {
      const level = ", " + num(100 * r.confidence, 0) + " % confidence";
      $("result-c").textContent = estimate(r.c_gcm2s2, 1e7, 4, " ×10⁷ g·cm²·s⁻²") + level;
      $("result-t").textContent = estimate(r.t_s, 1, 4, " s") + level;
      $("result-homogeneous").textContent = yesNo(r.homogeneous);
      $("result-adequate").textContent = yesNo(r.adequate);
      $("result-decision").textContent = s.decision || "no report yet";
    }
    const job = s.report;
    $("report-progress").hidden = !(job && (job.running || job.error));
    if (job) {
      $("report-stage").textContent = job.running ? "writing the report: " + job.stage
        : job.error ? "the report failed: " + job.error : "";
      $("report").disabled = job.running;
    }
    $("reports").hidden = !s.reports.length;
    const links = $("report-links");
    links.replaceChildren();
    for (const name of s.reports) {
      const a = document.createElement("a");
      a.href = location.pathname + "/files/" + encodeURIComponent(name);
      a.textContent = name;
      links.append(a, " ");
    }
  }

  const loaded = initial.status;  // a message of the action that led here is about this status
  function render(s) {
    window.stationUpdates += 1;
    window.stationAcquiring = s.acquiring;
    banner(s);
    result(s);
    if (s.status !== loaded && $("message")) $("message").remove();
    $("stop").hidden = !s.acquiring;
    $("resume").hidden = s.acquiring || s.status === "completed";
    prompt(s.prompt);
    $("process-error").textContent = s.process_error || "";
    const c = s.current;
    $("trial").textContent = c ? c.trial + "/" + s.n_trials + (c.attempt > 1 ? " (attempt " + c.attempt + ")" : "") : "-";
    $("series").textContent = c ? series(c.j) : "-";
    $("observation").textContent = c ? c.k + "/" + s.n_obs : "-";
    // a run that has ended shows its stand at rest, not the phase its last snapshot was in
    $("phase").textContent = s.prompt ? "stand stopped, " + WAITING : !c ? "done"
      : s.acquiring ? c.phase : "stand at rest (" + s.status + "), last in: " + c.phase;
    $("mean").textContent = c && c.mean_deg !== null ? num(c.mean_deg, 4) + "°" + (c.spread_deg === null ? "" : " (s = " + num(c.spread_deg, 4) + "°)") : "";
    $("settle").textContent = c && c.settle_estimate_deg !== null ? num(c.settle_estimate_deg, 4) + "°" : "";
    $("stand-time").textContent = hms(s.stand_time_s);
    $("eta").textContent = "stand " + hms(s.eta_stand_s) + ", wall " + hms(s.eta_wall_s);
    $("observations").textContent = s.observations + "/" + s.observations_planned;
    if (s.live) live(s.live, false);
    else $("heading-figure").hidden = true;
    trace(s.trace);
    const trials = $("trials").tBodies[0];
    trials.replaceChildren();
    for (const t of s.trials) {
      row(trials, [t.index + (t.attempt > 1 ? " #" + t.attempt : ""), t.role, t.status,
        (t.observations["1"] || 0) + "/" + s.n_obs, (t.observations["2"] || 0) + "/" + s.n_obs,
        t.commanded.map((v) => num(v, 1)).join(", "),
        t.measured[0] === null ? "" : t.measured.map((v) => num(v, 2)).join(", "), t.failure_reason]);
    }
    const events = $("events").tBodies[0];
    events.replaceChildren();
    for (const e of s.events) {
      row(events, [e.stand_time_s === null ? "" : hms(e.stand_time_s), e.wall_time, e.severity, e.kind, e.message], e.severity);
    }
  }

  render(initial);
  // open while the page is: a run resumed here or elsewhere streams on
  const source = new EventSource(location.pathname + "/stream");
  source.addEventListener("state", (ev) => render(JSON.parse(ev.data)));
  source.addEventListener("live", (ev) => live(JSON.parse(ev.data), true));
  source.addEventListener("end", () => {
    window.stationAcquiring = false;
  });
})();

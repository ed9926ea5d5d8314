// The front end of brdffit.explore (an anywidget module: JupyterLab, Notebook 7, VS Code).
// It shows what the Python side sends (_images, _info, _sliders, _models) and changes the model,
// the parameters, the light and the exposure (synced traits) or asks for an action (model.send).
// One change is in flight at a time: the next is sent when the view of the last has arrived
// (_info.frame), so a dragged slider shows its latest position rather than a queue of old ones.

const STEPS = 1000; // positions of a parameter slider
const RINGS = 81; // rows of the 81x81 tables: one per light direction

function make(tag, cls, parent, text) {
  const el = document.createElement(tag);
  if (cls) el.className = cls;
  if (text !== undefined) el.textContent = text;
  if (parent) parent.appendChild(el);
  return el;
}

function fmt(x) {
  return x === null || x === undefined ? "not finite" : Number(x).toPrecision(4);
}

function toValue(s, t) {
  const u = t / STEPS;
  return s.log ? s.lo * Math.pow(s.hi / s.lo, u) : s.lo + (s.hi - s.lo) * u;
}

function toPosition(s, v) {
  if (!(s.hi > s.lo)) return 0;
  const u = s.log ? Math.log(v / s.lo) / Math.log(s.hi / s.lo) : (v - s.lo) / (s.hi - s.lo);
  return Math.round(Math.min(1, Math.max(0, u)) * STEPS);
}

function render({ model, el }) {
  const root = make("div", "bf-explorer", el);
  const side = make("div", "bf-side", root);
  const views = make("div", "bf-views", root);

  // -- controls --------------------------------------------------------------------------------
  const head = make("div", "bf-head", side);
  const modelRow = make("label", "bf-row", side, "model ");
  const modelSelect = make("select", "bf-model", modelRow);
  const sliderBox = make("div", "bf-sliders", side);
  const lightBox = make("div", "bf-sliders bf-light", side);
  const buttons = make("div", "bf-buttons", side);
  const fitButton = make("button", "bf-fit", buttons, "Fit");
  const multiButton = make("button", "bf-multistart", buttons, "Multistart");
  const renderButton = make("button", "bf-render", buttons, "Render (Mitsuba)");
  const compareRow = make("div", "bf-row", side);
  const compareModels = make("input", "bf-compare-models", compareRow);
  compareModels.placeholder = "lambert, ggx, lambert+ggx";
  compareModels.title = "models to compare (comma-separated; empty: a few and the one shown)";
  const compareButton = make("button", "bf-compare", compareRow, "Compare");
  const exportRow = make("div", "bf-row", side);
  const exportPath = make("input", "bf-export-path", exportRow);
  exportPath.placeholder = "material.xml (.glb .gltf .mtlx .blend)";
  const exportTo = make("select", "bf-export-to", exportRow);
  const forceLabel = make("label", "bf-force", exportRow, "replace");
  const force = make("input", "", forceLabel);
  force.type = "checkbox";
  const exportButton = make("button", "bf-export", exportRow, "Export");
  const numbers = make("div", "bf-numbers", side);
  const loss = make("div", "bf-loss", numbers);
  const status = make("div", "bf-status", numbers);
  const warnings = make("ul", "bf-warnings", side);
  const message = make("div", "bf-message", side);

  // -- views -----------------------------------------------------------------------------------
  const images = {};
  function panel(names, caption, cls) {
    const fig = make("figure", `bf-panel ${cls || ""}`, views);
    const row = make("div", "bf-images", fig);
    let wrap;
    for (const [name, alt] of names) {
      wrap = make("div", "bf-wrap", row);
      images[name] = make("img", `bf-img bf-${name}`, wrap);
      images[name].alt = alt;
      images[name].dataset.name = name;
    }
    const figcaption = make("figcaption", "", fig, caption);
    return { fig, wrap, figcaption };
  }
  const tables = [panel([["measured", "measured table"]], "measured f_r (log scale; click a row to light from it)",
                        "bf-table"),
                  panel([["fitted", "model table"]], "model on the same scale", "bf-table")];
  const markers = tables.map(({ wrap }) => make("div", "bf-row-marker", wrap));
  const spheres = panel([["sphere_measured", "measured sphere"], ["sphere_fit", "model sphere"]], "", "bf-sphere");
  panel([["log_ratio", "log residual"]], "log residual per channel (R, G, B): red = model too bright, blue = too dark",
        "bf-residual");
  const slicesPanel = panel([["slices", "slices"]], "", "bf-wide");
  const pareto = panel([["pareto", "error against run time"]], "error against run time (Compare)", "bf-wide");

  // -- sending changes, one at a time --------------------------------------------------------------
  let pending = null;
  let inflight = false;
  let timer = null;
  function flush() {
    if (inflight || pending === null) return;
    let changed = false;
    for (const [key, value] of Object.entries(pending)) {
      if (JSON.stringify(model.get(key)) !== JSON.stringify(value)) {
        model.set(key, value);
        changed = true;
      }
    }
    pending = null;
    if (!changed) return;
    inflight = true;
    model.save_changes();
    timer = setTimeout(() => { inflight = false; flush(); }, 5000); // a lost reply does not block the sliders
  }
  function push(key, value) {
    pending = Object.assign(pending || {}, { [key]: value });
    flush();
  }
  function setBusy(text) {
    for (const b of side.querySelectorAll("button")) b.disabled = true;
    message.textContent = text;
    message.classList.remove("bf-error");
    root.classList.add("bf-busy");
  }
  function act(action, extra, text) {
    setBusy(text);
    model.send(Object.assign({ action }, extra || {}));
  }
  fitButton.onclick = () => act("fit", {}, "fitting from the values shown…");
  multiButton.onclick = () => act("multistart", {}, "fitting from the start grid…");
  renderButton.onclick = () => act("render", {}, "rendering in Mitsuba…");
  compareButton.onclick = () => act("compare", { models: compareModels.value }, "comparing models…");
  exportButton.onclick = () => act("export", { path: exportPath.value, to: exportTo.value, force: force.checked },
                                   "exporting…");
  for (const { wrap } of tables) {
    wrap.addEventListener("click", (e) => {
      const img = wrap.querySelector("img");
      const row = Math.floor((e.offsetY / img.clientHeight) * RINGS);
      act("light_row", { row: Math.min(RINGS - 1, Math.max(0, row)) }, "moving the light…");
    });
  }

  // -- sliders -------------------------------------------------------------------------------------
  function sliderRow(box, label, min, max, step, onInput) {
    const row = make("div", "bf-slider", box);
    make("span", "bf-label", row, label);
    const range = make("input", "bf-range", row);
    Object.assign(range, { type: "range", min, max, step });
    const number = make("input", "bf-number", row);
    number.type = "number";
    number.step = "any";
    range.addEventListener("input", () => onInput(Number(range.value), "range"));
    number.addEventListener("change", () => onInput(Number(number.value), "number"));
    return { row, range, number };
  }
  let paramRows = [];
  function buildSliders() {
    sliderBox.replaceChildren();
    paramRows = model.get("_sliders").map((s) => {
      const r = sliderRow(sliderBox, s.label, 0, STEPS, 1, (x, from) => {
        const value = from === "range" ? toValue(s, x) : x;
        if (from === "range") r.number.value = Number(value.toPrecision(4));
        const params = JSON.parse(JSON.stringify(model.get("_params")));
        const current = (pending && pending._params) || params;
        current[s.param][s.index] = value;
        push("_params", current);
      });
      r.row.dataset.param = s.param;
      r.row.dataset.index = s.index;
      r.range.title = `${s.lo.toPrecision(3)} … ${s.hi.toPrecision(3)} (${s.log ? "log" : "linear"})`;
      return { s, ...r };
    });
    syncSliders();
  }
  function syncSliders() {
    const params = model.get("_params");
    for (const { s, range, number } of paramRows) {
      const v = params[s.param] ? params[s.param][s.index] : undefined;
      if (v === undefined) continue;
      range.value = toPosition(s, v);
      number.value = Number(v.toPrecision(4));
    }
  }
  const theta = sliderRow(lightBox, "light θ°", 0, 89, 1, (x) => push("_light", [x, (pending && pending._light ? pending._light : model.get("_light"))[1]]));
  const phi = sliderRow(lightBox, "light φ°", 0, 359, 1, (x) => push("_light", [(pending && pending._light ? pending._light : model.get("_light"))[0], x]));
  const exposure = sliderRow(lightBox, "exposure", -6, 6, 0.1, (x) => push("_exposure", x));
  function syncLight() {
    const [t, p] = model.get("_light");
    theta.range.value = t;
    theta.number.value = Number(t.toFixed(1));
    phi.range.value = p;
    phi.number.value = Number(p.toFixed(1));
    exposure.range.value = model.get("_exposure");
    exposure.number.value = model.get("_exposure");
  }
  function buildModels() {
    modelSelect.replaceChildren();
    for (const name of model.get("_models")) make("option", "", modelSelect, name).value = name;
    modelSelect.value = model.get("_model");
  }
  modelSelect.onchange = () => push("_model", modelSelect.value);

  // -- what the Python side sends --------------------------------------------------------------------
  function showImages() {
    const data = model.get("_images");
    for (const [name, img] of Object.entries(images)) {
      if (data[name]) img.src = `data:image/png;base64,${data[name]}`;
    }
    pareto.fig.style.display = data.pareto ? "" : "none";
  }
  function showInfo() {
    const info = model.get("_info");
    head.textContent = `${info.data_name || ""}`;
    loss.textContent = `${info.loss_name} loss ${fmt(info.loss)} · rel_rmse ${fmt(info.rel_rmse)} · log_rmse ${fmt(info.log_rmse)}`;
    status.textContent = `${info.model}: ${info.status} · view ${info.ms} ms`;
    warnings.replaceChildren();
    for (const w of info.warnings || []) make("li", "", warnings, w);
    message.textContent = info.message || "";
    message.classList.toggle("bf-error", !!info.error);
    const [t, p] = model.get("_light");
    spheres.figcaption.textContent = `measured | model sphere (${info.spheres}), light θ = ${t}°, φ = ${p}°`;
    for (const m of markers) m.style.top = `${((info.light_row + 0.5) / RINGS) * 100}%`;
    slicesPanel.figcaption.textContent = `f_r (1/sr) against view θ at the measured light nearest to it ` +
      `(θ = ${info.slice_light}°): in-plane (top, + on the mirror side), cross-plane (bottom)`;
    const targets = ["", ...(info.native || [])];
    if (exportTo.options.length !== targets.length) {
      exportTo.replaceChildren();
      for (const t of targets) make("option", "", exportTo, t || "as shown").value = t;
    }
    for (const b of side.querySelectorAll("button")) b.disabled = false;
    root.classList.remove("bf-busy");
    root.dataset.frame = info.frame;
    clearTimeout(timer);
    inflight = false;
    flush();
  }
  const handlers = {
    "change:_images": showImages, "change:_info": showInfo, "change:_sliders": buildSliders,
    "change:_params": syncSliders, "change:_light": syncLight, "change:_exposure": syncLight,
    "change:_models": buildModels, "change:_model": buildModels,
  };
  for (const [event, fn] of Object.entries(handlers)) model.on(event, fn);
  buildModels();
  buildSliders();
  syncLight();
  showImages();
  showInfo();
  return () => {
    clearTimeout(timer);
    for (const [event, fn] of Object.entries(handlers)) model.off(event, fn);
  };
}

export default { render };

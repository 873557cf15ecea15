// /ui/new: start from an example or a stored study, edit the YAML, see the service's checks at their
// lines with the case count and the estimated time, submit.
"use strict";

const CHECK_DELAY_MS = 500;
let checked = null; // the last successful check: {definition, n_cases, ...}
let checkTimer = null;
let checkSeq = 0;
let problemLines = new Map(); // line -> [messages]

const text = () => $("#text");

// The gutter and the backdrop behind the text area are built from DOM nodes: every text (the study's
// own lines and the service's messages about them) goes in as a text node, never as markup.
function paint() {
  const lines = text().value.split("\n");
  const gutter = [];
  const backdrop = [];
  lines.forEach((l, i) => {
    const msgs = problemLines.get(i + 1);
    if (i) {
      gutter.push("\n");
      backdrop.push("\n");
    }
    if (msgs) {
      gutter.push(el("span", { class: "bad", title: msgs.join("\n") }, `⚠ ${i + 1}`));
      backdrop.push(el("span", { class: "bad" }, l || " "), el("span", { class: "note" }, `   ◀ ${msgs.join("; ")}`));
    } else {
      gutter.push(String(i + 1));
      backdrop.push(l);
    }
  });
  fill($("#gutter"), gutter);
  fill($("#backdrop"), backdrop, "\n");
  syncScroll();
}

function syncScroll() {
  $("#gutter").scrollTop = text().scrollTop;
  $("#backdrop").scrollTop = text().scrollTop;
  $("#backdrop").scrollLeft = text().scrollLeft;
}

function goToLine(line) {
  const lines = text().value.split("\n");
  const start = lines.slice(0, line - 1).reduce((n, l) => n + l.length + 1, 0);
  text().focus();
  text().setSelectionRange(start, start + (lines[line - 1] || "").length);
  const lineHeight = parseFloat(getComputedStyle(text()).lineHeight) || 18;
  text().scrollTop = Math.max(0, (line - 4) * lineHeight);
  syncScroll();
}

function where(d) {
  const loc = (d.loc || []).slice(2); // after ["body", "text"]
  return loc.length ? loc.map((p) => (typeof p === "number" ? `[${p}]` : `.${p}`)).join("").replace(/^\./, "") : "";
}

function showProblems(details) {
  problemLines = new Map();
  for (const d of details) {
    if (d.line) problemLines.set(d.line, [...(problemLines.get(d.line) || []), d.msg]);
  }
  fill($("#problems"), 
    ...details.map((d) =>
      el(
        "li",
        { "data-line": d.line || "", onclick: () => d.line && goToLine(d.line) },
        el("span", { class: "line" }, d.line ? `line ${d.line}` : "study"),
        where(d) ? el("code", {}, where(d) + ": ") : null,
        d.msg
      )
    )
  );
  paint();
}

async function check() {
  const seq = ++checkSeq;
  const body = text().value;
  checked = null;
  $("#submit").disabled = true;
  if (!body.trim()) {
    $("#check").textContent = "Write or load a study.";
    showProblems([]);
    return;
  }
  $("#check").textContent = "Checking…";
  try {
    const answer = await postJson("/studies/validate", { text: body });
    if (seq !== checkSeq) return;
    checked = answer;
    showProblems([]);
    $("#check").className = "check ok";
    $("#check").textContent = `✓ ${answer.name}: ${answer.n_cases} cases (${answer.parameters.join(" × ") || "no varied parameter"}), estimated time ${seconds(answer.estimated_seconds)}.`;
    $("#submit").disabled = false;
  } catch (err) {
    if (seq !== checkSeq) return;
    $("#check").className = "check error";
    const details = err.body && Array.isArray(err.body.detail) ? err.body.detail : [{ msg: err.message, loc: [] }];
    $("#check").textContent = `${details.length} problem${details.length === 1 ? "" : "s"}:`;
    showProblems(details);
  }
}

function scheduleCheck() {
  clearTimeout(checkTimer);
  paint();
  checkTimer = setTimeout(check, CHECK_DELAY_MS);
}

async function loadSources() {
  const select = $("#source");
  try {
    const examples = await apiJson("/examples");
    select.appendChild(el("optgroup", { label: "Examples" }, examples.names.map((n) => el("option", { value: `example:${n}` }, n))));
    const stored = await apiJson("/studies?limit=100");
    if (stored.items.length) {
      select.appendChild(
        el("optgroup", { label: "Stored studies" }, stored.items.map((s) => el("option", { value: `study:${s.id}` }, `${s.name} (${s.status}, ${when(s.created)})`)))
      );
    }
  } catch (err) {
    showError("#load-error", err);
  }
}

async function loadSource() {
  const [kind, key] = $("#source").value.split(/:(.*)/s);
  if (!key) return;
  try {
    if (kind === "example") {
      text().value = (await apiJson(`/examples/${encodeURIComponent(key)}`)).text;
    } else {
      const r = await api(`/studies/${encodeURIComponent(key)}/definition.yaml`);
      if (!r.ok) throw new ApiError(r.status, await r.json().catch(() => null));
      text().value = await r.text();
    }
    fill($("#load-error"));
    text().scrollTop = 0;
    scheduleCheck();
  } catch (err) {
    showError("#load-error", err);
  }
}

async function submit() {
  if (!checked) return;
  $("#submit").disabled = true;
  fill($("#submit-error"));
  try {
    const accepted = await postJson("/studies", checked.definition);
    location.href = `/ui/studies/${accepted.id}`;
  } catch (err) {
    $("#submit").disabled = false;
    if (err.body && Array.isArray(err.body.detail)) check();
    showError("#submit-error", err);
  }
}

header("new");
text().addEventListener("input", scheduleCheck);
text().addEventListener("scroll", syncScroll);
$("#load").addEventListener("click", loadSource);
$("#source").addEventListener("change", loadSource);
$("#submit").addEventListener("click", submit);
const preset = new URLSearchParams(location.search).get("from");
loadSources().then(() => {
  if (preset === "draft") {
    // a scene handed over by /ui/scene ("Start a study"), kept in this tab only
    text().value = sessionStorage.getItem("isolab-draft") || "";
    scheduleCheck();
  } else if (preset) {
    $("#source").value = preset;
    loadSource();
  }
});
paint();

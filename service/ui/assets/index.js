// /ui/: the studies in the catalog, live while any runs.
"use strict";

let studies = [];
let timer = null;

function render() {
  const q = $("#search").value.trim().toLowerCase();
  const shown = studies.filter((s) => !q || s.name.toLowerCase().includes(q));
  $("#count").textContent = `${shown.length} of ${studies.length} studies`;
  if (!shown.length) {
    fill($("#studies"), el("p", { class: "muted" }, studies.length ? "No study matches." : "No study yet."));
    return;
  }
  const rows = shown.map((s) =>
    el(
      "tr",
      { "data-id": s.id },
      el("td", {}, el("a", { href: `/ui/studies/${s.id}` }, s.name)),
      el("td", {}, statusBadge(s.status)),
      el("td", {}, progressBar(s.progress.done, s.progress.total, s.progress.failed)),
      el("td", { class: "num" }, s.progress.total),
      el("td", { class: "num" + (s.progress.failed ? " error" : "") }, s.progress.failed),
      el("td", {}, s.parameters.join(", ")),
      el("td", {}, s.isolator_types.join(", ")),
      el("td", {}, when(s.created)),
      el("td", { class: "error" }, s.error || "")
    )
  );
  fill($("#studies"), 
    el(
      "table",
      { id: "study-table" },
      el(
        "thead",
        {},
        el(
          "tr",
          {},
          ["Name", "Status", "Progress", "Cases", "Failed", "Parameters", "Isolators", "Created", "Error"].map((h) =>
            el("th", {}, h)
          )
        )
      ),
      el("tbody", {}, rows)
    )
  );
}

// "compiling the engine's kernels (first start only)" while the service warms its workers
async function refreshKernels() {
  let note = "";
  try {
    const health = await apiJson("/health");
    note = (health.kernels && health.kernels.note) || "";
  } catch (err) {
    note = ""; // a degraded service: the studies' own errors say more
  }
  $("#kernels").textContent = note;
  $("#kernels").hidden = !note;
  return Boolean(note);
}

async function refresh() {
  let warming = false;
  try {
    const [page, kernelsBusy] = await Promise.all([apiJson("/studies?limit=500"), refreshKernels()]);
    studies = page.items;
    warming = kernelsBusy;
    render();
  } catch (err) {
    showError("#studies", err);
  }
  const busy = warming || studies.some((s) => s.status === "queued" || s.status === "running");
  clearTimeout(timer);
  timer = setTimeout(refresh, busy ? 1500 : 10000);
}

header("studies");
$("#search").addEventListener("input", render);
refresh();

// isolab web page: what every view shares. Plain browser JavaScript, no build step.
// Every datum comes from the REST API; with a token set on the service, the page asks for it once, keeps
// it in this tab's sessionStorage and sends it as a bearer header on every request.
"use strict";

const TOKEN_KEY = "isolab-token";

class ApiError extends Error {
  constructor(status, body) {
    const detail = body && body.detail;
    const text = Array.isArray(detail) ? detail.map((d) => d.msg).join("; ") : detail || `HTTP ${status}`;
    super(text);
    this.status = status;
    this.body = body;
  }
}

let tokenPrompt = null; // one question at a time, however many requests were refused

function askToken(wrong) {
  if (tokenPrompt) return tokenPrompt;
  tokenPrompt = new Promise((resolve) => {
    const dialog = document.createElement("dialog");
    dialog.id = "token-dialog";
    const input = el("input", { id: "token-input", type: "password", autocomplete: "off", required: true, size: "40" });
    dialog.appendChild(
      el(
        "form",
        { method: "dialog" },
        el("h2", {}, "API token"),
        el("p", {}, "This isolab service wants a token (ISOLAB_API_TOKEN). It is kept in this tab only."),
        wrong ? el("p", { class: "error" }, "That token was refused.") : null,
        input,
        el("button", { id: "token-ok", type: "submit" }, "Use token")
      )
    );
    document.body.appendChild(dialog);
    dialog.addEventListener("close", () => {
      sessionStorage.setItem(TOKEN_KEY, dialog.querySelector("#token-input").value.trim());
      dialog.remove();
      tokenPrompt = null;
      resolve();
    });
    dialog.addEventListener("cancel", (e) => e.preventDefault());
    dialog.showModal();
  });
  return tokenPrompt;
}

async function api(path, options = {}) {
  for (let attempt = 0; ; attempt++) {
    const headers = new Headers(options.headers || {});
    const token = sessionStorage.getItem(TOKEN_KEY);
    if (token) headers.set("Authorization", `Bearer ${token}`);
    const response = await fetch(path, { ...options, headers });
    if (response.status !== 401 || attempt > 5) return response;
    await askToken(Boolean(token));
  }
}

async function apiJson(path, options = {}) {
  const response = await api(path, options);
  const text = await response.text();
  let body = null;
  try {
    body = text ? JSON.parse(text) : null;
  } catch (err) {
    body = { detail: text };
  }
  if (!response.ok) throw new ApiError(response.status, body);
  return body;
}

function postJson(path, data) {
  return apiJson(path, {
    method: "POST",
    headers: { "content-type": "application/json" },
    body: JSON.stringify(data),
  });
}

// A download of an API answer (the bearer header cannot ride on a plain link).
async function download(path, filename) {
  const response = await api(path);
  if (!response.ok) throw new ApiError(response.status, await response.json().catch(() => null));
  const url = URL.createObjectURL(await response.blob());
  const a = el("a", { href: url, download: filename });
  document.body.appendChild(a);
  a.click();
  a.remove();
  setTimeout(() => URL.revokeObjectURL(url), 10000);
}

// ------------------------------------------------------------------------------------------------ DOM
function el(tag, attrs = {}, ...children) {
  const node = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) {
    if (v === null || v === undefined || v === false) continue;
    if (k === "class") node.className = v;
    else if (k === "text") node.textContent = v;
    else if (k.startsWith("on")) node.addEventListener(k.slice(2), v);
    else node.setAttribute(k, v === true ? "" : v);
  }
  for (const c of children.flat(Infinity)) {
    if (c === null || c === undefined || c === false) continue;
    node.appendChild(typeof c === "string" || typeof c === "number" ? document.createTextNode(String(c)) : c);
  }
  return node;
}

const $ = (selector) => document.querySelector(selector);

// Replace a node's children (nested arrays flattened; null, undefined and false left out).
function fill(node, ...children) {
  const kids = children.flat(Infinity).filter((c) => c !== null && c !== undefined && c !== false);
  node.replaceChildren(...kids.map((c) => (typeof c === "string" || typeof c === "number" ? document.createTextNode(String(c)) : c)));
}

function showError(where, err) {
  const node = typeof where === "string" ? $(where) : where;
  if (node) fill(node, el("p", { class: "error" }, String(err.message || err)));
}

function header(active) {
  const links = [
    ["studies", "/ui/", "Studies"],
    ["scene", "/ui/scene", "Scene"],
    ["new", "/ui/new", "New study"],
    ["compare", "/ui/compare", "Compare isolators"],
    ["calibrate", "/ui/calibrate", "Calibrate"],
    ["docs", "/docs", "API reference"],
  ];
  const nav = el(
    "nav",
    {},
    el("a", { class: "brand", href: "/ui/" }, "isolab"),
    links.map(([key, href, label]) => el("a", { href, class: key === active ? "active" : null }, label))
  );
  document.body.prepend(el("header", {}, nav));
}

function statusBadge(status) {
  return el("span", { class: `badge status-${status}` }, status);
}

function progressBar(done, total, failed) {
  const pct = total > 0 ? Math.round((100 * done) / total) : 0;
  return el(
    "div",
    { class: "progress", title: `${done} of ${total} cases${failed ? `, ${failed} failed` : ""}` },
    el("div", { class: "bar", style: `width:${pct}%` }),
    el("span", {}, `${done} / ${total}`)
  );
}

// ------------------------------------------------------------------------------------------- numbers
// SI unit -> [unit shown, factor from SI]
const DISPLAY_UNITS = {
  m: ["mm", 1e3],
  rad: ["mrad", 1e3],
  "m/s": ["m/s", 1],
  "m/s^2": ["m/s²", 1],
  N: ["N", 1],
  s: ["s", 1],
  Hz: ["Hz", 1],
  "1": ["", 1],
  "": ["", 1],
};

function displayUnit(si) {
  return DISPLAY_UNITS[si] || [si, 1];
}

function fmt(value, digits = 4) {
  if (value === null || value === undefined) return "–";
  if (typeof value === "boolean") return value ? "yes" : "no";
  if (typeof value !== "number") return String(value);
  if (value === 0) return "0";
  const a = Math.abs(value);
  if (a >= 1e5 || a < 1e-3) return value.toExponential(digits - 1);
  return String(Number(value.toPrecision(digits)));
}

function seconds(s) {
  if (s === null || s === undefined) return "–";
  if (s < 1) return "under a second";
  if (s < 90) return `about ${Math.round(s)} s`;
  if (s < 5400) return `about ${Math.round(s / 60)} min`;
  return `about ${(s / 3600).toFixed(1)} h`;
}

function when(iso) {
  if (!iso) return "–";
  const d = new Date(iso.endsWith("Z") || iso.includes("+") ? iso : iso + "Z");
  return isNaN(d) ? iso : d.toLocaleString();
}

// ------------------------------------------------------------------------------------------- plots
const PLOT_CONFIG = { responsive: true, displaylogo: false };
const PALETTE = ["#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b", "#e377c2", "#17becf"];

// The study id of the page's address, encoded for a path (a crafted address cannot step out of
// /studies/{id}/... in the requests built from it).
function studyIdFromPath() {
  const m = location.pathname.match(/\/ui\/studies\/([^/]+)/);
  if (!m) return null;
  try {
    return encodeURIComponent(decodeURIComponent(m[1]));
  } catch (err) {
    return encodeURIComponent(m[1]);
  }
}

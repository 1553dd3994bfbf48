// SPDX-License-Identifier: Apache-2.0
// Browser test of report.html (ctest: report_browser, label report; issue 31).
//
//   node report_browser_test.mjs --plumb PLUMB --work DIR
//
// 1. `plumb reconstruct sim:living_room --frames 120 --no-baseline --out DIR/r` writes a report.
// 2. Headless Chromium (/usr/bin/chromium, driven by playwright-core from this folder's
//    node_modules, shared with the monitor's browser test) opens DIR/r/report.html from disk.
// 3. Every section is there; the page requests nothing (all pictures are data: URIs); every
//    picture (the model views' <img> and the top views' SVG <image>) decodes and is not blank:
//    drawn on a canvas, a good share of its pixels differ from the white background.
// 4. A screenshot is saved to DIR/report.png.
// Exit 0 on success, 1 on failure, 77 (ctest skip) when Chromium or playwright-core is missing
// outside CI; under CI=true a missing browser is a failure.
import { spawnSync } from "node:child_process";
import fs from "node:fs";
import path from "node:path";

import { CHROMIUM, harness } from "./harness.mjs";

const SECTIONS = ["Accuracy", "Model", "Warnings", "Walls", "Floor plan", "Top views",
                  "Energy per alternation iteration", "Time per stage"];

const { arg, fail, loadChromium } = harness("report_browser");

const plumb = arg("--plumb");
const work = arg("--work");
fs.rmSync(work, { recursive: true, force: true });
fs.mkdirSync(work, { recursive: true });

const chromium = await loadChromium();

const out = path.join(work, "r");
const run = spawnSync(plumb, ["--log-level", "warn", "reconstruct", "sim:living_room", "--frames", "120",
                              "--no-baseline", "--out", out], { encoding: "utf8" });
if (run.status !== 0) fail("plumb reconstruct exited with " + run.status + ": " + run.stderr);
const report = path.join(out, "report.html");
if (!fs.existsSync(report)) fail("no " + report);
const bytes = fs.statSync(report).size;
console.log("report_browser: " + report + " (" + bytes + " bytes)");
if (bytes > 2 * 1024 * 1024) fail("report.html is " + bytes + " bytes (> 2 MB)");

let browser;
try {
  browser = await chromium.launch({
    executablePath: CHROMIUM,
    headless: true,
    args: ["--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
           "--disable-background-networking", "--disable-component-update", "--disable-sync",
           "--disable-dev-shm-usage"],
  });
  const page = await browser.newPage({ viewport: { width: 1200, height: 900 } });
  const external = [];
  page.on("request", (req) => {
    const u = req.url();
    if (!u.startsWith("data:") && u !== "file://" + report) external.push(u);
  });
  const consoleErrors = [];
  page.on("console", (msg) => { if (msg.type() === "error") consoleErrors.push(msg.text()); });
  await page.goto("file://" + report, { waitUntil: "load" });

  const headings = await page.$$eval("h2", (hs) => hs.map((h) => h.textContent.trim()));
  const missing = SECTIONS.filter((s) => !headings.includes(s));
  if (missing.length) fail("sections missing: " + missing.join(", ") + " (page has: " + headings.join(", ") + ")");

  // Every picture: its source, and the share of non-white pixels once drawn on a canvas.
  const pictures = await page.evaluate(async () => {
    const sources = [...document.querySelectorAll("img")].map((i) => ["img", i.getAttribute("src")])
      .concat([...document.querySelectorAll("svg image")].map((i) => ["svg image", i.getAttribute("href")]));
    const results = [];
    for (const [kind, src] of sources) {
      const img = new Image();
      img.src = src;
      try { await img.decode(); } catch (e) { results.push({ kind, src: src.slice(0, 30), error: String(e) }); continue; }
      const c = document.createElement("canvas");
      c.width = img.naturalWidth; c.height = img.naturalHeight;
      const g = c.getContext("2d");
      g.drawImage(img, 0, 0);
      const d = g.getImageData(0, 0, c.width, c.height).data;
      let ink = 0;
      for (let k = 0; k < d.length; k += 4) if (d[k] < 245 || d[k + 1] < 245 || d[k + 2] < 245) ++ink;
      results.push({ kind, src: src.slice(0, 22), width: c.width, height: c.height, ink: ink / (c.width * c.height) });
    }
    return results;
  });
  console.log("report_browser: pictures " + JSON.stringify(pictures));
  if (pictures.filter((p) => p.kind === "img").length < 2) fail("fewer than 2 model pictures");
  if (pictures.filter((p) => p.kind === "svg image").length < 1) fail("no top-view picture");
  for (const p of pictures) {
    if (p.error) fail(p.kind + " does not decode: " + p.error);
    if (p.src !== "data:image/png;base64,") fail(p.kind + " is not an embedded PNG: " + p.src);
    if (!(p.ink > 0.03)) fail(p.kind + " " + p.width + "x" + p.height + " is blank (" + p.ink + " inked)");
  }
  const trajectory = await page.$$eval("svg.topview g.trajectory > *", (e) => e.length);
  if (trajectory < 1) fail("no camera path on the top view");
  const warnings = await page.$$eval("#warnings + *", (e) => e.length);
  if (warnings !== 1) fail("the warnings section is empty");
  if (external.length) fail("the page requested " + external.join(", "));
  if (consoleErrors.length) fail("console errors: " + consoleErrors.join("; "));

  const shot = path.join(work, "report.png");
  await page.screenshot({ path: shot, fullPage: true });
  const size = fs.statSync(shot).size;
  if (size < 10000) fail("screenshot is only " + size + " bytes");
  console.log("report_browser: screenshot " + shot + " (" + size + " bytes)");
  await browser.close();
  console.log("1 passed, 0 failed");
} catch (err) {
  if (browser) await browser.close().catch(() => {});
  fail(err.stack || String(err));
}

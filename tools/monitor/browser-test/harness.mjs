// SPDX-License-Identifier: Apache-2.0
// What the browser tests (monitor_browser_test.mjs, report_browser_test.mjs) share: reading their
// arguments, failing or skipping the way ctest reads it, and loading headless Chromium.
//
// A test prints "0 passed, 1 failed" and exits 1 on failure; it exits 77 (ctest skip) when
// Chromium or playwright-core is missing outside CI, and fails then under CI=true.
import fs from "node:fs";

export const CHROMIUM = process.env.PLUMB_CHROMIUM || "/usr/bin/chromium";

/// The helpers of the browser test called `name` (the prefix of its messages).
export function harness(name) {
  function arg(flag) {
    const i = process.argv.indexOf(flag);
    if (i < 0 || i + 1 >= process.argv.length) throw new Error("missing " + flag);
    return process.argv[i + 1];
  }
  function fail(message) {
    console.error(name + ": FAILED: " + message);
    console.log("0 passed, 1 failed");
    process.exit(1);
  }
  function unavailable(message) {
    if (process.env.CI === "true") fail(message + " (CI=true: the browser test must run; run tools/setup.sh)");
    console.log(name + ": skipped: " + message);
    process.exit(77);
  }
  /// playwright-core's chromium, once /usr/bin/chromium (or $PLUMB_CHROMIUM) is known to exist.
  async function loadChromium() {
    if (!fs.existsSync(CHROMIUM)) unavailable(CHROMIUM + " not found (Debian package chromium)");
    try {
      return (await import("playwright-core")).chromium;
    } catch (err) {
      unavailable("playwright-core not installed (tools/setup.sh runs npm ci in tools/monitor/browser-test): " + err.message);
    }
  }
  return { arg, fail, unavailable, loadChromium };
}

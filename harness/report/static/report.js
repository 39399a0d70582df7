/* sslpv-harness report: sortable tables, reference/SSLPV compare sliders and a
   self-check of the page (images loaded, no script errors) that headless tests read
   from <body data-images-ok data-errors>. Vanilla JS, no network. */
(function () {
  "use strict";
  var errors = [];

  function record(msg) {
    errors.push(String(msg));
    if (document.body) {
      document.body.dataset.errors = String(errors.length);
      var box = document.getElementById("report-errors");
      if (box) { box.textContent = errors.join("\n"); }
    }
  }

  // Capture phase: resource errors (a missing <img>) do not bubble.
  window.addEventListener("error", function (e) {
    var t = e.target;
    if (t && t !== window && (t.src || t.href)) { record("failed to load " + (t.src || t.href)); }
    else { record((e.message || "script error") + " at " + (e.filename || "?") + ":" + (e.lineno || "?")); }
  }, true);
  window.addEventListener("unhandledrejection", function (e) { record("unhandled rejection: " + e.reason); });
  var consoleError = console.error;
  console.error = function () {
    record(Array.prototype.join.call(arguments, " "));
    return consoleError.apply(console, arguments);
  };

  // ---- sortable tables: click a header; numbers sort numerically, blanks last
  function cellKey(row, idx) {
    var cell = row.cells[idx];
    if (!cell) { return ""; }
    return cell.hasAttribute("data-sort") ? cell.getAttribute("data-sort") : cell.textContent.trim();
  }

  function sortTable(table, idx, type, dir) {
    var body = table.tBodies[0];
    var rows = Array.prototype.slice.call(body.rows);
    rows.sort(function (a, b) {
      var x = cellKey(a, idx), y = cellKey(b, idx);
      if (x === "" && y === "") { return 0; }
      if (x === "") { return 1; }
      if (y === "") { return -1; }
      var r;
      if (type === "num") {
        var fx = parseFloat(x), fy = parseFloat(y);
        r = (isNaN(fx) || isNaN(fy)) ? x.localeCompare(y) : fx - fy;
      } else {
        r = x.localeCompare(y, undefined, { numeric: true });
      }
      return dir === "ascending" ? r : -r;
    });
    rows.forEach(function (r) { body.appendChild(r); });
  }

  function initSortable(table) {
    var heads = table.tHead ? table.tHead.rows[0].cells : [];
    Array.prototype.forEach.call(heads, function (th, idx) {
      th.tabIndex = 0;
      function go() {
        var dir = th.getAttribute("aria-sort") === "ascending" ? "descending" : "ascending";
        Array.prototype.forEach.call(heads, function (h) { h.removeAttribute("aria-sort"); });
        th.setAttribute("aria-sort", dir);
        sortTable(table, idx, th.dataset.type || "text", dir);
      }
      th.addEventListener("click", go);
      th.addEventListener("keydown", function (e) { if (e.key === "Enter" || e.key === " ") { e.preventDefault(); go(); } });
    });
  }

  // ---- compare: the slider moves the split; a click swaps between reference and SSLPV
  function initCompare(fig) {
    var box = fig.querySelector(".compare"), slider = fig.querySelector(".slider");
    if (!box || !slider) { return; }
    var overlay = box.querySelector(".overlay"), divider = box.querySelector(".divider");
    function set(pct) {
      overlay.style.clipPath = "inset(0 0 0 " + pct + "%)";
      divider.style.left = pct + "%";
      divider.style.display = (pct <= 0 || pct >= 100) ? "none" : "";
      slider.value = String(pct);
    }
    slider.addEventListener("input", function () { set(Number(slider.value)); });
    box.addEventListener("click", function () {
      // 0: all SSLPV, 100: all reference; from a split, go to SSLPV first.
      set(Number(slider.value) === 0 ? 100 : 0);
    });
    set(Number(slider.value));
  }

  function checkImages() {
    var imgs = Array.prototype.slice.call(document.images);
    var broken = imgs.filter(function (im) { return !im.complete || im.naturalWidth === 0; });
    document.body.dataset.imagesTotal = String(imgs.length);
    document.body.dataset.imagesBroken = broken.map(function (im) { return im.getAttribute("src"); }).join(" ");
    document.body.dataset.imagesOk = broken.length === 0 ? "true" : "false";
    document.body.dataset.errors = String(errors.length);
    var box = document.getElementById("report-errors");
    if (box) { box.textContent = errors.join("\n"); }
    document.body.dataset.checked = "true";
  }

  document.addEventListener("DOMContentLoaded", function () {
    document.body.dataset.errors = String(errors.length);
    Array.prototype.forEach.call(document.querySelectorAll("table.sortable"), initSortable);
    Array.prototype.forEach.call(document.querySelectorAll("figure"), initCompare);
  });
  window.addEventListener("load", checkImages);
})();

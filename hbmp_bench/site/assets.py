"""The leaderboard website's stylesheet and script, written as ``assets/site.css`` and ``assets/site.js``.

Kept here as text (not as package data files) so that every install of the package can build the site.
The script is vanilla JavaScript with no library: sorting on a header click and filter forms.
"""

SITE_CSS = r"""/* The leaderboard website: one small stylesheet, no framework. */
body { font: 15px/1.45 system-ui, -apple-system, "Segoe UI", sans-serif; margin: 0; color: #1d232a; background: #fff; }
header { background: #1f3b57; color: #fff; padding: 0.6rem 1.5rem; }
header a { color: #fff; margin-right: 1.2rem; text-decoration: none; }
header a:hover { text-decoration: underline; }
main { padding: 0.5rem 1.5rem 3rem; max-width: 110rem; }
h1 { font-size: 1.6rem; margin: 1rem 0 0.3rem; }
h2 { font-size: 1.25rem; margin: 2rem 0 0.4rem; border-bottom: 1px solid #d6dde4; }
h3 { font-size: 1.05rem; margin: 1.2rem 0 0.3rem; }
p.note, .note { color: #4a5663; font-size: 0.9rem; max-width: 70rem; }
code { font: 0.86em ui-monospace, SFMono-Regular, Menlo, monospace; background: #f1f4f7; padding: 0 0.2em; border-radius: 3px; }
table { border-collapse: collapse; margin: 0.4rem 0 1rem; font-size: 0.88rem; }
th, td { border: 1px solid #d6dde4; padding: 0.2rem 0.45rem; text-align: right; vertical-align: top; }
td { white-space: nowrap; }
td.wrap { white-space: normal; min-width: 16rem; }
.scroll { overflow-x: auto; max-width: 100%; }
th { background: #eef2f6; position: sticky; top: 0; }
td.text, th.text { text-align: left; }
table.sortable th { cursor: pointer; user-select: none; }
table.sortable th[aria-sort=ascending]::after { content: " \25B2"; font-size: 0.7em; }
table.sortable th[aria-sort=descending]::after { content: " \25BC"; font-size: 0.7em; }
tbody tr:nth-child(even) { background: #f8fafb; }
tr[hidden] { display: none; }
form.filters { display: flex; flex-wrap: wrap; gap: 0.8rem; align-items: center; margin: 0.4rem 0; font-size: 0.9rem; }
form.filters label { display: flex; gap: 0.3rem; align-items: center; }
.count { color: #4a5663; font-size: 0.85rem; }
.good { color: #17663a; }
.bad { color: #a1261b; }
details { margin: 0.3rem 0; }
summary { cursor: pointer; }
img.figure { max-width: 100%; border: 1px solid #d6dde4; margin: 0.5rem 0; }
dl.facts { display: grid; grid-template-columns: max-content 1fr; gap: 0.15rem 1rem; font-size: 0.9rem; }
dl.facts dt { font-weight: 600; }
dl.facts dd { margin: 0; overflow-wrap: anywhere; }
"""
"""``assets/site.css``."""

SITE_JS = r"""// The leaderboard website's tables: click a header to sort, use a table's filter form to hide rows.
// No library, no build step. A sortable table is <table class="sortable" id="T">; a cell's sort key is
// its data-sort attribute, else its text; a column sorts as numbers when every key in it is a number.
// A filter form <form class="filters" data-for="T"> holds <select name="K"> (a row passes when its
// data-K, a space-separated list, holds the chosen value) and <input name="q"> (text the row contains).
"use strict";

(function () {
  function key(cell) {
    return cell.hasAttribute("data-sort") ? cell.getAttribute("data-sort") : cell.textContent.trim();
  }

  function isNumber(text) {
    return text !== "" && isFinite(Number(text));
  }

  function sortBy(table, column, header) {
    var body = table.tBodies[0];
    var rows = Array.prototype.slice.call(body.rows);
    var keys = rows.map(function (row) { return key(row.cells[column]); });
    var numeric = keys.every(function (k) { return k === "" || isNumber(k); });
    var ascending = header.getAttribute("aria-sort") !== "ascending";
    var order = rows.map(function (row, i) { return i; });
    order.sort(function (a, b) {
      var x = keys[a], y = keys[b], c;
      if (numeric) {
        c = (x === "" ? -Infinity : Number(x)) - (y === "" ? -Infinity : Number(y));
      } else {
        c = x.localeCompare(y);
      }
      return (ascending ? c : -c) || a - b;
    });
    Array.prototype.forEach.call(header.parentNode.cells, function (th) { th.removeAttribute("aria-sort"); });
    header.setAttribute("aria-sort", ascending ? "ascending" : "descending");
    order.forEach(function (i) { body.appendChild(rows[i]); });
  }

  function filter(form) {
    var table = document.getElementById(form.getAttribute("data-for"));
    var selects = form.querySelectorAll("select");
    var text = form.querySelector("input[name=q]");
    var needle = text ? text.value.trim().toLowerCase() : "";
    var shown = 0;
    Array.prototype.forEach.call(table.tBodies[0].rows, function (row) {
      var pass = Array.prototype.every.call(selects, function (select) {
        var wanted = select.value;
        if (!wanted) { return true; }
        var values = (row.getAttribute("data-" + select.name) || "").split(" ");
        return values.indexOf(wanted) >= 0;
      });
      if (pass && needle) { pass = row.textContent.toLowerCase().indexOf(needle) >= 0; }
      row.hidden = !pass;
      if (pass) { shown += 1; }
    });
    var count = document.querySelector("[data-count-for='" + table.id + "']");
    if (count) { count.textContent = shown + " of " + table.tBodies[0].rows.length + " rows"; }
  }

  document.addEventListener("DOMContentLoaded", function () {
    Array.prototype.forEach.call(document.querySelectorAll("table.sortable"), function (table) {
      Array.prototype.forEach.call(table.tHead.rows[0].cells, function (th, column) {
        th.tabIndex = 0;
        th.title = "sort by " + th.textContent.trim();
        th.addEventListener("click", function () { sortBy(table, column, th); });
        th.addEventListener("keydown", function (e) {
          if (e.key === "Enter" || e.key === " ") { e.preventDefault(); sortBy(table, column, th); }
        });
      });
    });
    Array.prototype.forEach.call(document.querySelectorAll("form.filters"), function (form) {
      form.addEventListener("input", function () { filter(form); });
      form.addEventListener("change", function () { filter(form); });
      form.addEventListener("submit", function (e) { e.preventDefault(); });
      filter(form);
    });
  });
})();
"""
"""``assets/site.js``: sortable tables (``table.sortable``) and filter forms (``form.filters``)."""

// Plotly (vendor/plotly-basic.min.js, a classic deferred script) is executed after this module
// graph, so the page's first requests overlap with its start-up; draw through `plot`, which waits.

const ready = new Promise((resolve) => {
  if (window.Plotly) resolve(window.Plotly);
  else document.addEventListener("DOMContentLoaded", () => resolve(window.Plotly));
});

// A chart narrower than this is a phone's: one curve panel a row, the map's legend lower, and no
// toolbar (it sat on the panels' titles, and a tap shows it).
export const NARROW_PX = 560;

export async function plot(element, traces, layout) {
  const Plotly = await ready;
  const toolbar = element.clientWidth >= NARROW_PX ? "hover" : false;
  return Plotly.react(element, traces, layout, { responsive: true, displaylogo: false, displayModeBar: toolbar });
}

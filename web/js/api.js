// The service's HTTP API and streams, with the operator's token.
// The token arrives once as ?token=… (what `collie up` prints), is kept for the tab's lifetime in
// sessionStorage and removed from the address bar, so it is not left in history or screenshots.

const KEY = "collie-token";

export class ApiError extends Error {
  constructor(status, detail) {
    // FastAPI's validation errors are a list of {loc, msg, …}: their messages say enough
    const text = Array.isArray(detail) && detail.every((d) => d?.msg) ? detail.map((d) => d.msg).join("; ") : detail;
    super(typeof text === "string" ? text : JSON.stringify(text));
    this.status = status;
  }
}

export function takeTokenFromUrl() {
  const url = new URL(window.location.href);
  const token = url.searchParams.get("token");
  if (token) {
    sessionStorage.setItem(KEY, token);
    url.searchParams.delete("token");
    window.history.replaceState(null, "", url.pathname + url.search + url.hash);
  }
}

export const token = () => sessionStorage.getItem(KEY) || "";
export const setToken = (value) => sessionStorage.setItem(KEY, value);

export async function api(path, { method = "GET", body } = {}) {
  const headers = { Authorization: `Bearer ${token()}` };
  if (body !== undefined) headers["Content-Type"] = "application/json";
  const response = await fetch(`api/${path}`, {
    method, headers, body: body === undefined ? undefined : JSON.stringify(body),
  });
  const data = await response.json().catch(() => null);
  if (!response.ok) throw new ApiError(response.status, data?.detail ?? response.statusText);
  return data;
}

// Server-Sent Events: `handlers` maps event names to callbacks of the parsed data. The browser
// reconnects by itself and resumes with Last-Event-ID; `onState` hears "live" / "down".
export function stream(path, params, handlers, onState) {
  const query = new URLSearchParams({ ...params, access_token: token() });
  const source = new EventSource(`api/${path}?${query}`);
  for (const [name, handle] of Object.entries(handlers)) {
    source.addEventListener(name, (event) => handle(JSON.parse(event.data)));
  }
  source.onopen = () => onState?.("live");
  source.onerror = () => onState?.(source.readyState === EventSource.CLOSED ? "closed" : "down");
  return source;
}

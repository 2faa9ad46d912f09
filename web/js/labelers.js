// Labeler management (operator token): create a labeler (name → a token shown once, and a labeler
// link into the labeling UI), list every principal, revoke a labeler's token (a second click
// confirms; operator and trainer tokens are not revoked from here, so the page cannot lock itself out).

import { api } from "./api.js";
import { escapeHtml } from "./format.js";

// The labeling UI signs a tab in from ?token= (labeling_ui/browser.py) and drops it from the address.
export function labelerLink(uiUrl, token) {
  if (!uiUrl) return null;
  return `${uiUrl}${uiUrl.includes("?") ? "&" : "?"}${new URLSearchParams({ token })}`;
}

async function copy(input, button) {
  input.select();
  try {
    await navigator.clipboard.writeText(input.value);
  } catch {
    document.execCommand("copy"); // plain http: the Clipboard API is only for secure origins
  }
  const text = button.textContent;
  button.textContent = "Copied";
  setTimeout(() => { button.textContent = text; }, 1500);
}

const NAME_CHARS = /^[A-Za-z0-9_.:+-]+$/; // what the service takes (collie/schemas.py Name)
const MAX_NAME = 64;

function nameProblem(name) {
  if (!name) return "give the labeler a name";
  if (name.length > MAX_NAME) return `a name has at most ${MAX_NAME} characters (this one has ${name.length})`;
  if (!NAME_CHARS.test(name)) return "a name may hold only A–Z a–z 0–9 _ . : + - (no spaces or accents)";
  return null;
}

export class LabelerPanel {
  // `onRefused(reason)`: the service refused the token (401); the page asks for another (main.js).
  constructor(root, uiUrl, onRefused) {
    this.root = root;
    this.uiUrl = uiUrl;
    this.onRefused = onRefused;
    this.body = root.querySelector("#labelers-body");
    this.message = root.querySelector("#labeler-message");
    this.armed = null;
    root.querySelector("#labeler-name").addEventListener("input", () => { this.message.textContent = ""; });
    root.querySelector("#labeler-form").addEventListener("submit", (event) => {
      event.preventDefault();
      this.create(root.querySelector("#labeler-name").value.trim());
    });
    root.querySelector("#copy-token").addEventListener("click", (e) => copy(root.querySelector("#created-token"), e.target));
    root.querySelector("#copy-link").addEventListener("click", (e) => copy(root.querySelector("#created-link"), e.target));
    this.body.addEventListener("click", (event) => {
      const button = event.target.closest("button[data-revoke]");
      if (button) this.revoke(Number(button.dataset.revoke), button);
    });
  }

  async load() {
    try {
      const people = await api("labelers");
      this.enable(true);
      this.render(people);
    } catch (error) {
      if (error.status === 401) {
        this.onRefused(error.message);
        return;
      }
      this.body.innerHTML = `<tr><td colspan="5" class="muted">${
        error.status === 403 ? "only an operator's token may manage labelers" : escapeHtml(error.message)}</td></tr>`;
      this.enable(error.status !== 403);
    }
  }

  // No token the service takes: `rowHtml` (the page's one message) in the table, the form disabled.
  lock(rowHtml) {
    this.body.innerHTML = rowHtml;
    this.root.querySelector("#labeler-created").hidden = true;
    this.message.textContent = "";
    this.enable(false);
  }

  enable(on) {
    for (const control of this.root.querySelectorAll("#labeler-form input, #labeler-form button")) control.disabled = !on;
  }

  render(people) {
    this.body.innerHTML = people.map((p) => `
      <tr data-labeler="${escapeHtml(p.name)}" class="${p.revoked ? "revoked" : ""}">
        <td>${escapeHtml(p.name)}</td><td>${p.role}</td><td>${new Date(p.created_at).toLocaleString()}</td>
        <td>${p.revoked ? "revoked" : "active"}</td>
        <td>${p.revoked || p.role !== "labeler" ? "" : `<button type="button" class="danger" data-revoke="${p.id}">Revoke</button>`}</td>
      </tr>`).join("") || '<tr><td colspan="5" class="muted">nobody yet</td></tr>';
  }

  async create(name) {
    this.message.textContent = "";
    this.root.querySelector("#labeler-created").hidden = true; // an earlier token is not this attempt's
    const wrong = nameProblem(name);
    if (wrong) {
      this.message.textContent = wrong;
      return;
    }
    try {
      const made = await api("labelers", { method: "POST", body: { name, role: "labeler" } });
      const link = labelerLink(this.uiUrl, made.token);
      this.root.querySelector("#created-name").textContent = made.name;
      this.root.querySelector("#created-token").value = made.token;
      this.root.querySelector("#created-link").value = link ?? "";
      this.root.querySelector("#created-link-row").hidden = link == null;
      this.root.querySelector("#created-no-link").hidden = link != null;
      this.root.querySelector("#labeler-created").hidden = false;
      this.root.querySelector("#labeler-name").value = "";
      await this.load();
    } catch (error) {
      this.message.textContent = error.message; // the service names what is wrong (a taken name, a bad character)
    }
  }

  disarm() {
    if (this.armed) {
      this.armed.textContent = "Revoke";
      this.armed.classList.remove("confirm");
    }
    this.armed = null;
  }

  async revoke(id, button) {
    if (this.armed !== button) { // the first click arms (and disarms another), the second revokes
      this.disarm();
      this.armed = button;
      button.textContent = "Confirm revoke";
      button.classList.add("confirm");
      return;
    }
    this.armed = null;
    try {
      await api(`labelers/${id}`, { method: "DELETE" });
      this.message.textContent = "";
      this.root.querySelector("#labeler-created").hidden = true; // a shown token may be the revoked one
    } catch (error) {
      this.message.textContent = error.message;
    }
    await this.load();
  }
}

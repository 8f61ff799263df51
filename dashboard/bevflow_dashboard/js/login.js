// The login page: log in and go where the user was headed, or, on a first run, create the first
// administrator with the one-time setup token from the gateway's log (in the URL's #setup=...,
// which browsers never send to a server, so it stays out of proxies' logs).

const $ = (id) => document.getElementById(id);

/** Where to go after logging in: `?next=` if it is a path on this site, else the dashboard. */
export function nextPage(search) {
  const next = new URLSearchParams(search).get("next") || "/";
  return next.startsWith("/") && !next.startsWith("//") ? next : "/";
}

/** POST `body` as JSON to `path`; resolves to the parsed answer, or throws an Error whose message
 * is the gateway's explanation (wrong password, too many attempts, ...). */
async function post(path, body) {
  let response;
  try {
    response = await fetch(path, {
      method: "POST",
      headers: { "Content-Type": "application/json", Accept: "application/json" },
      body: JSON.stringify(body),
      credentials: "same-origin",
    });
  } catch {
    throw new Error("The gateway does not answer; check the connection and try again.");
  }
  const answer = await response.json().catch(() => ({}));
  if (!response.ok) {
    const detail = typeof answer.detail === "string" ? answer.detail : answer.message;
    if (response.status === 401) throw new Error("Wrong user name or password.");
    if (response.status === 429) {
      const wait = response.headers.get("Retry-After");
      throw new Error(`Too many failed attempts. Try again in ${wait || "a few"} seconds.`);
    }
    throw new Error(detail || `The gateway refused (HTTP ${response.status}).`);
  }
  return answer;
}

function showError(node, message) {
  node.textContent = message;
  node.hidden = !message;
}

function bindForm(form, errorNode, submit) {
  form.addEventListener("submit", async (event) => {
    event.preventDefault();
    const button = form.querySelector("button[type=submit]");
    button.disabled = true;
    showError(errorNode, "");
    try {
      await submit(new FormData(form));
      location.assign(nextPage(location.search));
    } catch (error) {
      showError(errorNode, error.message);
      button.disabled = false;
      form.querySelector("input[type=password]").select();
    }
  });
}

function setUp() {
  const setupToken = new URLSearchParams(location.hash.slice(1)).get("setup");
  if (new URLSearchParams(location.search).has("logged_out")) {
    $("login-notice").textContent = "You are logged out.";
    $("login-notice").hidden = false;
  }
  bindForm($("login-form"), $("login-error"), (form) => post("/api/auth/login", { name: form.get("name").trim(), password: form.get("password") }));
  if (setupToken) {
    $("login-form").hidden = true;
    $("setup-form").hidden = false;
    $("setup-name").focus();
    bindForm($("setup-form"), $("setup-error"), async (form) => {
      if (form.get("password") !== form.get("again")) throw new Error("The two passwords differ.");
      await post("/api/auth/setup", { token: setupToken, name: form.get("name").trim(), password: form.get("password") });
      history.replaceState(null, "", location.pathname); // the token is used up
    });
  }
  document.body.dataset.ready = "true";
}

setUp();

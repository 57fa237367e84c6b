//! Who may talk to the daemon. A local daemon must not be drivable by the web pages its user visits:
//!
//! - **Host**: every request must name the daemon by an address it listens on, `localhost` on loopback, or a name
//!   the user allowed (`--allow-host`). A page on `evil.example` whose name an attacker re-points at 127.0.0.1
//!   (DNS rebinding) sends `Host: evil.example` and is refused, so it cannot read readings or frames.
//! - **Origin**: requests that change something (anything but GET/HEAD/OPTIONS) and WebSocket upgrades must come
//!   from the daemon's own page (`Origin` equal to the address the request was sent to), or carry the token
//!   explicitly (header or query). Browsers always send `Origin` on these requests and a page cannot forge it;
//!   a request without `Origin` comes from a program (curl, a script), which the Host check and the loopback
//!   binding already confine, and which could forge any header it liked.
//! - **Token** (when set): every request carries it as `Authorization: Bearer <token>`, `?token=<token>`, or the
//!   cookie the dashboard gets when it is opened as `/?token=<token>` (then redirected to `/`, so the token
//!   leaves the address bar). Compared in constant time. The cookie is `SameSite=Strict` and `HttpOnly`, and a
//!   request that relies on it still passes the Origin check: a cookie is ambient, a page elsewhere could
//!   make the browser send it.

use std::collections::HashMap;
use std::net::{IpAddr, SocketAddr};

use axum::extract::{Query, Request, State};
use axum::http::{header, HeaderMap, Method, StatusCode, Uri};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use subtle::ConstantTimeEq;

use super::{ApiError, AppState};

/// The daemon's rules for Host, Origin and token; built once at start.
#[derive(Debug)]
pub struct AccessPolicy {
    token: Option<Vec<u8>>,
    /// Names (lower case, no port, no trailing dot) the daemon answers to.
    hosts: Vec<String>,
    /// Listening on every interface: any IP literal names this machine (a page cannot rebind an IP literal).
    any_ip: bool,
    cookie_name: String,
}

impl AccessPolicy {
    /// `listen` is the bound address (with its real port); `allowed_hosts` the names the user added.
    pub fn new(listen: SocketAddr, allowed_hosts: &[String], token: Option<&str>) -> Self {
        let mut hosts: Vec<String> = allowed_hosts.iter().map(|h| normalise_host(h)).collect();
        let ip = listen.ip();
        hosts.push(normalise_host(&host_literal(ip)));
        if ip.is_loopback() || ip.is_unspecified() {
            hosts.extend(["localhost", "127.0.0.1", "[::1]"].map(String::from));
        }
        if ip.is_unspecified() {
            if let Some(name) = machine_hostname() {
                hosts.push(format!("{name}.local"));
                hosts.push(name);
            }
        }
        hosts.sort();
        hosts.dedup();
        Self {
            token: token.filter(|t| !t.is_empty()).map(|t| t.as_bytes().to_vec()),
            hosts,
            any_ip: ip.is_unspecified(),
            // Cookies are not kept apart by port: two daemons on one machine must not overwrite each other's.
            cookie_name: format!("nusense_token_{}", listen.port()),
        }
    }

    pub fn token_required(&self) -> bool {
        self.token.is_some()
    }

    /// The names the daemon answers to, for messages.
    pub fn hosts(&self) -> &[String] {
        &self.hosts
    }

    fn host_allowed(&self, host: &str) -> bool {
        let name = normalise_host(host_without_port(host));
        if self.hosts.contains(&name) {
            return true;
        }
        self.any_ip
            && name
                .trim_start_matches('[')
                .trim_end_matches(']')
                .parse::<IpAddr>()
                .is_ok()
    }

    fn token_matches(&self, presented: &[u8]) -> bool {
        match &self.token {
            Some(expected) => bool::from(expected.as_slice().ct_eq(presented)),
            None => false,
        }
    }
}

/// How a request identified itself.
enum Credential {
    /// Authorization header or `?token=`: the sender knows the token, so it is not a page elsewhere.
    Explicit,
    /// Only the dashboard's cookie: ambient, so the Origin check still applies.
    Cookie,
    None,
}

pub async fn guard(State(state): State<AppState>, request: Request, next: Next) -> Response {
    let policy = &state.access;
    let Some(host) = request_host(&request) else {
        return ApiError::new(StatusCode::BAD_REQUEST, "the request names no Host").into_response();
    };
    if !policy.host_allowed(&host) {
        return ApiError::new(
            StatusCode::FORBIDDEN,
            format!(
                "this daemon does not answer to the name `{host}` (it answers to {}); if you reach it under \
                 another name, start it with --allow-host NAME",
                policy.hosts.join(", ")
            ),
        )
        .into_response();
    }

    let credential = match credential(policy, request.headers(), request.uri()) {
        Ok(credential) => credential,
        Err(refusal) => return refusal.into_response(),
    };

    let changes_state = !matches!(*request.method(), Method::GET | Method::HEAD | Method::OPTIONS);
    if (changes_state || is_websocket_upgrade(request.headers())) && !matches!(credential, Credential::Explicit) {
        if let Err(refusal) = same_origin(request.headers(), &host) {
            return refusal.into_response();
        }
    }

    // The dashboard opened as `/?token=...`: keep the token in a cookie and take it out of the address bar.
    if matches!(credential, Credential::Explicit) && request.uri().path() == "/" && query_token(request.uri()).is_some()
    {
        let token_hex = policy.token.as_deref().map(hex_encode).unwrap_or_default();
        let cookie = format!("{}={token_hex}; Path=/; HttpOnly; SameSite=Strict", policy.cookie_name);
        return (
            StatusCode::SEE_OTHER,
            [(header::LOCATION, "/".to_string()), (header::SET_COOKIE, cookie)],
        )
            .into_response();
    }
    next.run(request).await
}

fn credential(policy: &AccessPolicy, headers: &HeaderMap, uri: &Uri) -> Result<Credential, ApiError> {
    if !policy.token_required() {
        return Ok(Credential::None);
    }
    let bearer = headers
        .get(header::AUTHORIZATION)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.strip_prefix("Bearer "))
        .map(|t| t.trim().as_bytes().to_vec());
    let explicit = bearer.or_else(|| query_token(uri).map(String::into_bytes));
    if let Some(token) = explicit {
        return if policy.token_matches(&token) {
            Ok(Credential::Explicit)
        } else {
            Err(ApiError::new(StatusCode::UNAUTHORIZED, "wrong token"))
        };
    }
    if let Some(token) = cookie_token(headers, &policy.cookie_name) {
        return if policy.token_matches(&token) {
            Ok(Credential::Cookie)
        } else {
            Err(ApiError::new(
                StatusCode::UNAUTHORIZED,
                "the token this browser remembers is no longer the daemon's: open the dashboard as /?token=<token>",
            ))
        };
    }
    Err(ApiError::new(
        StatusCode::UNAUTHORIZED,
        "this daemon requires a token: open the dashboard as /?token=<token>, or send `Authorization: Bearer \
         <token>`",
    ))
}

/// The `Origin` of a state-changing request or WebSocket upgrade must be the address the request went to.
fn same_origin(headers: &HeaderMap, host: &str) -> Result<(), ApiError> {
    let refuse = |origin: &str| {
        ApiError::new(
            StatusCode::FORBIDDEN,
            format!(
                "cross-site request refused: it comes from the page {origin}, not from this daemon's own page \
                 (http://{host}); programs may send the token instead"
            ),
        )
    };
    match headers.get(header::ORIGIN) {
        Some(origin) => {
            let origin = origin.to_str().unwrap_or("(not text)");
            let authority = origin
                .strip_prefix("http://")
                .or_else(|| origin.strip_prefix("https://"))
                .ok_or_else(|| refuse(origin))?;
            if authority.eq_ignore_ascii_case(host) {
                Ok(())
            } else {
                Err(refuse(origin))
            }
        }
        // A browser that left Origin out still says where the request came from.
        None => match headers.get("sec-fetch-site").and_then(|v| v.to_str().ok()) {
            Some("cross-site" | "same-site") => Err(refuse("of another site")),
            _ => Ok(()),
        },
    }
}

fn is_websocket_upgrade(headers: &HeaderMap) -> bool {
    headers
        .get(header::UPGRADE)
        .and_then(|v| v.to_str().ok())
        .is_some_and(|v| v.eq_ignore_ascii_case("websocket"))
}

fn request_host(request: &Request) -> Option<String> {
    request
        .headers()
        .get(header::HOST)
        .and_then(|v| v.to_str().ok())
        .map(str::to_string)
        .or_else(|| request.uri().authority().map(|a| a.to_string()))
}

fn query_token(uri: &Uri) -> Option<String> {
    let Query(query) = Query::<HashMap<String, String>>::try_from_uri(uri).ok()?;
    query.get("token").cloned()
}

fn cookie_token(headers: &HeaderMap, name: &str) -> Option<Vec<u8>> {
    headers
        .get_all(header::COOKIE)
        .iter()
        .filter_map(|v| v.to_str().ok())
        .flat_map(|v| v.split(';'))
        .filter_map(|pair| pair.trim().split_once('='))
        .find(|(key, _)| *key == name)
        .and_then(|(_, value)| hex_decode(value))
}

/// `host:port`, `[v6]:port`, `host`, `[v6]` -> the part before the port.
fn host_without_port(host: &str) -> &str {
    if host.starts_with('[') {
        return host.find(']').map_or(host, |end| &host[..=end]);
    }
    match host.rsplit_once(':') {
        Some((name, port)) if port.chars().all(|c| c.is_ascii_digit()) => name,
        _ => host,
    }
}

fn normalise_host(host: &str) -> String {
    host.trim_end_matches('.').to_ascii_lowercase()
}

fn host_literal(ip: IpAddr) -> String {
    match ip {
        IpAddr::V4(v4) => v4.to_string(),
        IpAddr::V6(v6) => format!("[{v6}]"),
    }
}

fn machine_hostname() -> Option<String> {
    let name = std::fs::read_to_string("/proc/sys/kernel/hostname").ok()?;
    let name = normalise_host(name.trim());
    (!name.is_empty()).then_some(name)
}

// Cookie values may not hold every character a token can: the cookie carries the token's bytes in hex.
fn hex_encode(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

fn hex_decode(text: &str) -> Option<Vec<u8>> {
    if !text.len().is_multiple_of(2) {
        return None;
    }
    (0..text.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(text.get(i..i + 2)?, 16).ok())
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn loopback() -> AccessPolicy {
        AccessPolicy::new("127.0.0.1:8750".parse().unwrap(), &["sensor.lab".into()], None)
    }

    #[test]
    fn loopback_answers_to_its_own_names_only() {
        let policy = loopback();
        for host in [
            "127.0.0.1:8750",
            "localhost:8750",
            "LOCALHOST",
            "[::1]:8750",
            "sensor.lab",
            "localhost.",
        ] {
            assert!(policy.host_allowed(host), "{host}");
        }
        for host in [
            "evil.example",
            "evil.example:8750",
            "127.0.0.1.evil.example",
            "192.168.1.5:8750",
            "",
        ] {
            assert!(!policy.host_allowed(host), "{host}");
        }
    }

    #[test]
    fn every_interface_accepts_ip_literals_but_not_foreign_names() {
        let policy = AccessPolicy::new("0.0.0.0:8750".parse().unwrap(), &[], Some("t"));
        assert!(policy.host_allowed("192.168.1.5:8750"));
        assert!(policy.host_allowed("[fe80::1]:8750"));
        assert!(!policy.host_allowed("evil.example:8750"));
    }

    #[test]
    fn tokens_compare_exactly() {
        let policy = AccessPolicy::new("127.0.0.1:1".parse().unwrap(), &[], Some("secret"));
        assert!(policy.token_matches(b"secret"));
        assert!(!policy.token_matches(b"secreT"));
        assert!(!policy.token_matches(b"secret2"));
        assert!(!policy.token_matches(b""));
        assert!(!loopback().token_matches(b""), "no token configured matches nothing");
    }

    #[test]
    fn origin_must_be_the_address_the_request_went_to() {
        let mut headers = HeaderMap::new();
        assert!(
            same_origin(&headers, "127.0.0.1:8750").is_ok(),
            "a program sends no Origin"
        );
        headers.insert(header::ORIGIN, "http://127.0.0.1:8750".parse().unwrap());
        assert!(same_origin(&headers, "127.0.0.1:8750").is_ok());
        for origin in ["http://evil.example", "http://127.0.0.1:9999", "null", "file://"] {
            headers.insert(header::ORIGIN, origin.parse().unwrap());
            assert!(same_origin(&headers, "127.0.0.1:8750").is_err(), "{origin}");
        }
        let mut headers = HeaderMap::new();
        headers.insert("sec-fetch-site", "cross-site".parse().unwrap());
        assert!(same_origin(&headers, "127.0.0.1:8750").is_err());
    }

    #[test]
    fn cookie_values_round_trip_any_token() {
        let token = "a b;c=d,é";
        let mut headers = HeaderMap::new();
        headers.insert(
            header::COOKIE,
            format!("other=1; nusense_token_8750={}", hex_encode(token.as_bytes()))
                .parse()
                .unwrap(),
        );
        assert_eq!(cookie_token(&headers, "nusense_token_8750").unwrap(), token.as_bytes());
        assert_eq!(cookie_token(&headers, "nusense_token_1"), None);
        assert_eq!(hex_decode("zz"), None);
    }
}

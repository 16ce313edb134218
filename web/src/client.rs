//! A participant without a browser: a blocking HTTP/1.1 client of the page's API over one
//! kept-alive connection, for the load benchmark and the API tests (loopback only).

use std::collections::BTreeMap;
use std::io::{BufRead as _, BufReader, Read as _, Write as _};
use std::net::{SocketAddr, TcpStream};

use serde_json::Value;

/// One HTTP reply.
#[derive(Debug, Clone)]
pub struct Reply {
    /// Status code.
    pub status: u16,
    /// Body.
    pub body: Vec<u8>,
}

impl Reply {
    /// The body as JSON (`Null` when it is not).
    pub fn json(&self) -> Value {
        serde_json::from_slice(&self.body).unwrap_or(Value::Null)
    }
}

/// A connection to a server, with the participant's subject and token once joined.
pub struct Client {
    addr: SocketAddr,
    conn: Option<BufReader<TcpStream>>,
    /// Subject id.
    pub subject: String,
    /// Session token.
    pub token: String,
}

impl Client {
    /// A client of the server at `addr` (connects on the first request).
    pub fn new(addr: SocketAddr) -> Client {
        Client {
            addr,
            conn: None,
            subject: String::new(),
            token: String::new(),
        }
    }

    /// Sends one request (reconnecting once if the kept-alive connection was closed).
    ///
    /// # Errors
    /// The server cannot be reached or sent no valid reply.
    pub fn request(
        &mut self,
        method: &str,
        path: &str,
        body: Option<&Value>,
    ) -> std::io::Result<Reply> {
        if let Ok(r) = self.try_request(method, path, body) {
            return Ok(r);
        }
        self.conn = None;
        self.try_request(method, path, body)
    }

    fn try_request(
        &mut self,
        method: &str,
        path: &str,
        body: Option<&Value>,
    ) -> std::io::Result<Reply> {
        if self.conn.is_none() {
            let s = TcpStream::connect(self.addr)?;
            s.set_nodelay(true)?;
            self.conn = Some(BufReader::new(s));
        }
        let Some(conn) = self.conn.as_mut() else {
            return Err(std::io::Error::other("no connection"));
        };
        let request = request_text(method, path, self.addr, &self.token, body);
        conn.get_mut().write_all(request.as_bytes())?;
        let mut line = String::new();
        if conn.read_line(&mut line)? == 0 {
            return Err(std::io::Error::other("connection closed"));
        }
        let mut head = ReplyHead::from_status_line(&line)?;
        loop {
            line.clear();
            conn.read_line(&mut line)?;
            if !head.header(&line) {
                break;
            }
        }
        let (status, len, close) = (head.status, head.length, head.close);
        let mut body = vec![0u8; len];
        conn.read_exact(&mut body)?;
        if close {
            self.conn = None;
        }
        Ok(Reply { status, body })
    }

    /// Joins with URL parameters `params` and a browser that passes the default check.
    ///
    /// # Errors
    /// The request failed; the reply is returned whatever its status.
    pub fn join(&mut self, params: &BTreeMap<String, String>) -> std::io::Result<Reply> {
        let body = serde_json::json!({ "params": params, "environment": environment() });
        let r = self.request("POST", "/api/join", Some(&body))?;
        if r.status == 200 {
            let v = r.json();
            self.subject = v["subject"].as_str().unwrap_or_default().to_string();
            self.token = v["token"].as_str().unwrap_or_default().to_string();
        }
        Ok(r)
    }

    /// `path` under this participant's API (`/api/s/{subject}/{path}`).
    pub fn session_path(&self, path: &str) -> String {
        format!("/api/s/{}/{path}", self.subject)
    }
}

/// A whole request: its head (the participant's token, when there is one) and its JSON body.
pub fn request_text(
    method: &str,
    path: &str,
    host: SocketAddr,
    token: &str,
    body: Option<&Value>,
) -> String {
    let body = body.map(Value::to_string).unwrap_or_default();
    let auth = if token.is_empty() {
        String::new()
    } else {
        format!("Authorization: Bearer {token}\r\n")
    };
    format!(
        "{method} {path} HTTP/1.1\r\nHost: {host}\r\n{auth}Content-Type: application/json\r\nContent-Length: {}\r\n\r\n{body}",
        body.len()
    )
}

/// What a reply's status line and headers said, read line by line.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ReplyHead {
    /// Status code.
    pub status: u16,
    /// `Content-Length` (0 without it).
    pub length: usize,
    /// `Connection: close`.
    pub close: bool,
}

impl ReplyHead {
    /// The head begun by status line `line`.
    ///
    /// # Errors
    /// A line without a status code.
    pub fn from_status_line(line: &str) -> std::io::Result<Self> {
        let status = line
            .split(' ')
            .nth(1)
            .and_then(|c| c.parse().ok())
            .ok_or_else(|| std::io::Error::other(format!("bad status line {line:?}")))?;
        Ok(Self {
            status,
            length: 0,
            close: false,
        })
    }

    /// Takes header line `line`; false at the empty line that ends the head.
    pub fn header(&mut self, line: &str) -> bool {
        let l = line.trim_end();
        if l.is_empty() {
            return false;
        }
        if let Some((k, v)) = l.split_once(':') {
            let k = k.to_ascii_lowercase();
            if k == "content-length" {
                self.length = v.trim().parse().unwrap_or(0);
            } else if k == "connection" && v.trim().eq_ignore_ascii_case("close") {
                self.close = true;
            }
        }
        true
    }
}

/// The environment of a 60 Hz desktop browser, as a page reports it.
pub fn environment() -> Value {
    serde_json::json!({
        "webgl2": true,
        "webgl_renderer": "test",
        "user_agent": "web::client",
        "screen_px": [1920, 1080],
        "window_px": [1280, 800],
        "device_pixel_ratio": 1.0,
        "refresh_hz": 60.0,
        "fullscreen": false,
    })
}

//! The nginx configuration of the documented deployment (`docs/serve.md`, "Several servers
//! on one database"): nginx in front of several `study serve --store` processes, spreading
//! requests over them; a request whose server is gone is passed to the next one, answers
//! too (a server acknowledges a repeated answer once, so passing it again cannot log it
//! twice). The tests and the load benchmark run nginx with exactly this text, on loopback.

use std::fmt::Write as _;
use std::net::SocketAddr;
use std::path::Path;

/// How nginx spreads the participants' requests.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Balance {
    /// Round robin: consecutive requests of one participant go to different servers (each
    /// takes the session over by replay); what the tests use, to move sessions as often as
    /// possible.
    RoundRobin,
    /// By the participant's id in the path (consistent hashing): a participant stays on one
    /// server while it lives, so sessions move only when a server goes.
    Participant,
}

/// A whole `nginx.conf` (run in the foreground with `nginx -c FILE -p PREFIX`) that listens
/// on `listen` (plain HTTP: terminate TLS in front of it, or add `ssl` to `listen` with a
/// certificate), passes requests to `upstreams` as `balance` says, and keeps its pid file,
/// logs and temporary folders under `prefix`.
pub fn config(
    upstreams: &[SocketAddr],
    listen: SocketAddr,
    balance: Balance,
    prefix: &Path,
) -> String {
    let d = prefix.display();
    let mut servers = String::new();
    for a in upstreams {
        // A server that failed once is left out for 30 s (nginx tries it again then). At
        // most 256 requests in flight to each, under the server's cap of 512 connections
        // per address (a request over it gets 502, which the page asks again, instead of a
        // closed connection that would count as the server's failure).
        let _ = writeln!(
            servers,
            "        server {a} max_fails=1 fail_timeout=30s max_conns=256;"
        );
    }
    let hash = match balance {
        Balance::RoundRobin => "",
        Balance::Participant => "        hash $participant consistent;\n",
    };
    format!(
        "daemon off;
worker_processes 1;
worker_rlimit_nofile 16384;
pid {d}/nginx.pid;
error_log {d}/nginx-error.log warn;
events {{
    worker_connections 8192;
}}
http {{
    access_log off;
    client_body_temp_path {d}/nginx-body;
    proxy_temp_path {d}/nginx-proxy;
    fastcgi_temp_path {d}/nginx-fastcgi;
    uwsgi_temp_path {d}/nginx-uwsgi;
    scgi_temp_path {d}/nginx-scgi;
    # The participant's id, from /api/s/{{subject}}/...
    map $uri $participant {{
        ~^/api/s/(?<id>[^/]+)/ $id;
        default \"\";
    }}
    upstream study {{
{hash}{servers}        keepalive 64;
    }}
    server {{
        listen {listen};
        client_max_body_size 256k;
        client_header_timeout 10s;
        client_body_timeout 30s;
        location / {{
            proxy_pass http://study;
            proxy_http_version 1.1;
            proxy_set_header Connection \"\";
            proxy_set_header Host $host;
            proxy_set_header X-Forwarded-For $proxy_add_x_forwarded_for;
            proxy_next_upstream error timeout http_502 non_idempotent;
            proxy_connect_timeout 2s;
            proxy_read_timeout 60s;
            proxy_buffers 16 64k;
            proxy_max_temp_file_size 0;
        }}
    }}
}}
"
    )
}

//! The protocol over TCP, as a host tool meets it: bad frames, unknown commands and
//! out-of-range values each get an error reply naming the problem, and none of them
//! changes the drive (its state, its settings, the board's event log).

use acim_firmware_core::protocol::{command_frame, unframe};
use acim_firmware_core::settings::FIELD_COUNT;
use acim_vboard::server::{self, Options, Pace, ServerHandle};
use std::io::{BufRead, BufReader, Write};
use std::net::{TcpListener, TcpStream};
use std::time::Duration;

struct Conn {
    w: TcpStream,
    r: BufReader<TcpStream>,
}

impl Conn {
    fn open(srv: &ServerHandle) -> Conn {
        let s = TcpStream::connect(srv.local_addr()).unwrap();
        s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
        let mut c = Conn {
            w: s.try_clone().unwrap(),
            r: BufReader::new(s),
        };
        let hello = c.line();
        assert!(hello.starts_with("$V,1,5000,acim-vboard"), "{hello}");
        assert_eq!(c.line(), "acim-vboard ready (help for commands)");
        c
    }

    fn line(&mut self) -> String {
        let mut l = String::new();
        self.r
            .read_line(&mut l)
            .unwrap_or_else(|e| panic!("no reply line: {e}"));
        l.trim_end().to_string()
    }

    /// Sends raw bytes and reads reply lines until one that ends a reply.
    fn ask(&mut self, raw: &[u8]) -> Vec<String> {
        self.w.write_all(raw).unwrap();
        let mut out = Vec::new();
        loop {
            let l = self.line();
            let body = match unframe(l.as_bytes()) {
                Ok((_, p)) => String::from_utf8_lossy(p).to_string(),
                Err(_) => l.clone(),
            };
            let done = body.starts_with("ok") || body.starts_with("err");
            out.push(l);
            if done {
                return out;
            }
        }
    }

    fn framed(&mut self, cmd: &str) -> Vec<String> {
        self.ask(&command_frame(cmd))
    }
}

fn start() -> ServerHandle {
    server::start(
        TcpListener::bind("127.0.0.1:0").unwrap(),
        Options {
            pace: Pace::Factor(5.0),
            rate: None,
        },
    )
    .unwrap()
}

#[test]
fn bad_input_gets_an_error_and_changes_nothing() {
    let srv = start();
    let mut c = Conn::open(&srv);
    let settings = c.ask(b"get\r\n");
    assert_eq!(settings.len(), FIELD_COUNT + 1, "{settings:?}");
    assert_eq!(c.ask(b"status\r\n"), ["ok state 0 fault 00"]);

    let cases: &[(&[u8], &str)] = &[
        (b"frobnicate\r\n", "err unknown command (try help)"),
        (b"START\r\n", "err unknown command (try help)"),
        (b"speed 1801\r\n", "err out of range"),
        (b"speed fast\r\n", "err bad number"),
        (b"speed 1e3\r\n", "err bad number"),
        (b"load 21\r\n", "err out of range"),
        (b"rate 1\r\n", "err out of range"),
        (
            b"set limits.current_limit 99\r\n",
            "err (limits.overcurrent_trip: ",
        ),
        (
            b"set limits.current_limit -1\r\n",
            "err (limits.current_limit: ",
        ),
        (
            b"set machine.pole_pairs 2.5\r\n",
            "err (machine.pole_pairs: must be a whole number in 1..=32)",
        ),
        (b"set bogus 1\r\n", "err unknown setting (get lists them)"),
        (b"sta\xffrt\r\n", "err non-ASCII byte"),
        (&[b'x'; 200], ""),
        (b"\r\n", "err line too long"),
        (b"$C,start*0000\r\n", "$E,err bad frame: checksum*"),
        (
            b"$C,start\r\n",
            "$E,err bad frame: expected $C,<command>*HHHH*",
        ),
        (b"$T,1,2*1234\r\n", "$E,err bad frame: "),
    ];
    for (raw, want) in cases {
        if want.is_empty() {
            c.w.write_all(raw).unwrap();
            continue;
        }
        let r = c.ask(raw);
        assert_eq!(r.len(), 1, "{r:?}");
        assert!(
            r[0].starts_with(want),
            "{:?}: {r:?}",
            String::from_utf8_lossy(raw)
        );
    }
    // framed: the same refusals, framed
    let r = c.framed("speed 9999");
    assert!(r[0].starts_with("$E,err out of range*"), "{r:?}");
    let r = c.framed("set limits.current_limit 99");
    assert!(
        r[0].starts_with("$E,err (limits.overcurrent_trip: "),
        "{r:?}"
    );
    // a corrupted frame of a valid command is not executed
    let mut f = command_frame("start").to_vec();
    f[4] ^= 0x20; // "start" -> "sTart"
    let r = c.ask(&f);
    assert!(r[0].starts_with("$E,err bad frame: checksum"), "{r:?}");

    assert_eq!(c.ask(b"get\r\n"), settings);
    assert_eq!(c.ask(b"status\r\n"), ["ok state 0 fault 00"]);
    assert!(srv.log().is_empty(), "{:?}", srv.log());

    // while running: a bad stop frame does not stop it, a refused set does not touch it
    assert_eq!(c.framed("start").len(), 1);
    let mut stop = command_frame("stop").to_vec();
    stop[3] = b'S';
    assert!(c.ask(&stop)[0].starts_with("$E,err bad frame: checksum"));
    let r = c.ask(b"set limits.current_limit 4\r\n");
    assert_eq!(
        r,
        ["err limits.current_limit: refused while the drive is not idle (stop or reset first)"]
    );
    std::thread::sleep(Duration::from_millis(50));
    let r = c.framed("status");
    assert!(
        r[0].starts_with("$R,ok state 1 fault 00*") || r[0].starts_with("$R,ok state 2 fault 00*"),
        "{r:?}"
    );
    assert_eq!(c.ask(b"get\r\n"), settings);
    assert_eq!(srv.log().len(), 1, "{:?}", srv.log());
    srv.shutdown();
}

#[test]
fn replies_and_version() {
    let srv = start();
    let mut c = Conn::open(&srv);
    let r = c.framed("version");
    let (k, p) = unframe(r[0].as_bytes()).unwrap();
    assert_eq!(k, b'R');
    assert!(String::from_utf8_lossy(p).starts_with("ok protocol 1 board acim-vboard"));
    assert!(c.ask(b"help\r\n")[0].contains("rate <periods>"));
    assert_eq!(
        c.ask(b"get limits.current_limit\r\n"),
        ["limits.current_limit = 4.67 A", "ok"]
    );
    assert_eq!(
        c.ask(b"set limits.current_limit 4\r\n"),
        ["ok limits.current_limit applied (save to keep it)"]
    );
    assert_eq!(
        c.ask(b"get limits.current_limit\r\n"),
        ["limits.current_limit = 4 A", "ok"]
    );
    srv.shutdown();
}

//! Blocking TCP transport: one [`Connection`] per peer, with read and write timeouts and
//! `TCP_NODELAY`, messages written whole and read whole (length prefix first, checked against
//! [`MAX_MESSAGE_LEN`](crate::MAX_MESSAGE_LEN) before the body is allocated). The crate
//! documentation says why threads and blocking sockets.

use std::io::{ErrorKind, Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream, ToSocketAddrs};
use std::time::Duration;

use crate::protocol::{Message, PREFIX_LEN};
use crate::NetError;

/// One end of a TCP connection carrying [`Message`]s, with byte counters.
pub struct Connection {
    stream: TcpStream,
    peer: String,
    timeout: Duration,
    sent: u64,
    received: u64,
}

impl Connection {
    /// Connects to `addr` (host:port), waiting at most `timeout` for the connection and for
    /// each later read or write.
    pub fn connect(addr: &str, timeout: Duration) -> Result<Connection, NetError> {
        let io = |op, source| NetError::Io { peer: addr.to_string(), op, source };
        let addrs: Vec<SocketAddr> =
            addr.to_socket_addrs().map_err(|e| io("resolve the address", e))?.collect();
        let mut last = None;
        for a in addrs {
            match TcpStream::connect_timeout(&a, timeout) {
                Ok(stream) => return Connection::new(stream, addr.to_string(), timeout),
                Err(e) => last = Some(e),
            }
        }
        Err(io("connect", last.unwrap_or_else(|| ErrorKind::AddrNotAvailable.into())))
    }

    /// Wraps an accepted stream (blocking, `TCP_NODELAY`, `timeout` on reads and writes).
    pub fn new(stream: TcpStream, peer: String, timeout: Duration) -> Result<Connection, NetError> {
        let io = |op, source| NetError::Io { peer: peer.clone(), op, source };
        stream.set_nonblocking(false).map_err(|e| io("configure the socket", e))?;
        stream.set_nodelay(true).map_err(|e| io("set TCP_NODELAY", e))?;
        stream.set_read_timeout(Some(timeout)).map_err(|e| io("set the read timeout", e))?;
        stream.set_write_timeout(Some(timeout)).map_err(|e| io("set the write timeout", e))?;
        Ok(Connection { stream, peer, timeout, sent: 0, received: 0 })
    }

    /// The peer, as connected to or accepted from.
    pub fn peer(&self) -> &str {
        &self.peer
    }

    /// Bytes written so far (length prefixes included; TCP/IP headers not).
    pub fn bytes_sent(&self) -> u64 {
        self.sent
    }

    /// Bytes read so far.
    pub fn bytes_received(&self) -> u64 {
        self.received
    }

    /// Sends `messages` in one write (a frame's delta chunks and its sentinel leave together:
    /// one system call, and with `TCP_NODELAY` no wait for an acknowledgement in between).
    pub fn send(&mut self, messages: &[Message]) -> Result<(), NetError> {
        let mut bytes = Vec::new();
        for m in messages {
            let encoded = m.encode().map_err(|source| NetError::Wire {
                peer: self.peer.clone(),
                offset: self.sent + bytes.len() as u64,
                source,
            })?;
            bytes.extend_from_slice(&encoded);
        }
        self.stream.write_all(&bytes).map_err(|e| self.io_error("send", e))?;
        self.sent += bytes.len() as u64;
        Ok(())
    }

    /// Reads one message, waiting at most the timeout for each part of it.
    pub fn receive(&mut self) -> Result<Message, NetError> {
        let offset = self.received;
        let wire = |peer: &str, source| NetError::Wire { peer: peer.to_string(), offset, source };
        let mut prefix = [0u8; PREFIX_LEN];
        self.read_exact(&mut prefix)?;
        let len = Message::body_len(prefix).map_err(|e| wire(&self.peer, e))?;
        let mut body = vec![0u8; len];
        self.read_exact(&mut body)?;
        Message::decode_body(&body).map_err(|e| wire(&self.peer, e))
    }

    /// Waits up to `wait` for the start of a message; false when none began (the connection
    /// stays usable: nothing was consumed). For loops that must check a stop flag between
    /// messages without giving up on an idle peer.
    pub fn readable_within(&mut self, wait: Duration) -> Result<bool, NetError> {
        let set = |s: &TcpStream, t| s.set_read_timeout(Some(t));
        set(&self.stream, wait.max(Duration::from_millis(1)))
            .map_err(|e| self.io_error("set the read timeout", e))?;
        let mut byte = [0u8; 1];
        let result = self.stream.peek(&mut byte);
        set(&self.stream, self.timeout).map_err(|e| self.io_error("set the read timeout", e))?;
        match result {
            Ok(0) => Err(NetError::Closed { peer: self.peer.clone() }),
            Ok(_) => Ok(true),
            Err(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => Ok(false),
            Err(e) if e.kind() == ErrorKind::Interrupted => Ok(false),
            Err(e) => Err(self.io_error("receive", e)),
        }
    }

    /// Closes both directions now (a peer blocked on a read sees the end at once).
    pub fn shutdown(&self) {
        let _ = self.stream.shutdown(std::net::Shutdown::Both);
    }

    fn read_exact(&mut self, buf: &mut [u8]) -> Result<(), NetError> {
        self.stream.read_exact(buf).map_err(|e| self.io_error("receive", e))?;
        self.received += buf.len() as u64;
        Ok(())
    }

    fn io_error(&self, op: &'static str, e: std::io::Error) -> NetError {
        let peer = self.peer.clone();
        match e.kind() {
            ErrorKind::WouldBlock | ErrorKind::TimedOut => {
                NetError::Timeout { peer, op, after: self.timeout }
            }
            ErrorKind::UnexpectedEof | ErrorKind::ConnectionReset | ErrorKind::BrokenPipe => {
                NetError::Closed { peer }
            }
            _ => NetError::Io { peer, op, source: e },
        }
    }
}

/// A listening socket that can be polled, so that a server loop can check a stop flag (Ctrl-C)
/// between connections.
pub struct Listener {
    listener: TcpListener,
    timeout: Duration,
}

impl Listener {
    /// Listens on `addr` (port 0: any free port, see [`local_addr`](Self::local_addr));
    /// accepted connections get `timeout` on their reads and writes.
    pub fn bind(addr: &str, timeout: Duration) -> Result<Listener, NetError> {
        let io = |op, source| NetError::Io { peer: addr.to_string(), op, source };
        let listener = TcpListener::bind(addr).map_err(|e| io("listen", e))?;
        listener.set_nonblocking(true).map_err(|e| io("configure the socket", e))?;
        Ok(Listener { listener, timeout })
    }

    pub fn local_addr(&self) -> Result<SocketAddr, NetError> {
        self.listener.local_addr().map_err(|e| NetError::Io {
            peer: "listener".into(),
            op: "read the listening address",
            source: e,
        })
    }

    /// The next connection, waiting up to `wait` for one.
    pub fn accept_within(&self, wait: Duration) -> Result<Option<Connection>, NetError> {
        let poll = Duration::from_millis(10).min(wait);
        let start = std::time::Instant::now();
        loop {
            match self.listener.accept() {
                Ok((stream, peer)) => {
                    return Connection::new(stream, peer.to_string(), self.timeout).map(Some)
                }
                Err(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::Interrupted) => {
                    if start.elapsed() >= wait {
                        return Ok(None);
                    }
                    std::thread::sleep(poll);
                }
                Err(e) => return Err(NetError::Io { peer: "listener".into(), op: "accept", source: e }),
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::protocol::{HelloReply, MAX_MESSAGE_LEN};

    fn pair() -> (Connection, Connection) {
        let listener = Listener::bind("127.0.0.1:0", Duration::from_secs(5)).unwrap();
        let addr = listener.local_addr().unwrap().to_string();
        let client = Connection::connect(&addr, Duration::from_millis(300)).unwrap();
        let server = listener.accept_within(Duration::from_secs(5)).unwrap().unwrap();
        (client, server)
    }

    #[test]
    fn messages_cross_and_are_counted() {
        let (mut a, mut b) = pair();
        let m = [Message::HelloReply(HelloReply::Accept { server: "s".into() }), Message::Bye];
        a.send(&m).unwrap();
        assert_eq!(b.receive().unwrap(), m[0]);
        assert_eq!(b.receive().unwrap(), m[1]);
        assert_eq!(a.bytes_sent(), b.bytes_received());
        assert_eq!(a.bytes_sent(), (4 + 1 + 4 + 1) + (4 + 1));
    }

    #[test]
    fn silence_is_a_timeout_and_a_close_is_closed() {
        let (mut a, b) = pair();
        assert!(!a.readable_within(Duration::from_millis(20)).unwrap());
        assert!(matches!(a.receive(), Err(NetError::Timeout { .. })));
        drop(b);
        assert!(matches!(a.receive(), Err(NetError::Closed { .. })));
    }

    #[test]
    fn a_huge_length_prefix_is_refused_before_reading_the_body() {
        let (a, mut b) = pair();
        let mut raw = a.stream.try_clone().unwrap();
        raw.write_all(&(MAX_MESSAGE_LEN + 1).to_le_bytes()).unwrap();
        let e = b.receive().unwrap_err();
        assert!(e.to_string().contains("stream byte 0") && e.to_string().contains("length"), "{e}");
    }
}

//! The gRPC edge's reading side of a client connection, with a client's RST_STREAM on a stream it
//! never opened taken out before h2 reads it.
//!
//! gRPC's C core (the C++, Python, C#, Ruby and PHP clients) sends RST_STREAM for a call cancelled
//! before its HEADERS were written: the stream id is taken, the HEADERS dropped, the reset sent
//! (grpc/grpc issues 19655 and 38758). RFC 9113 section 6.4 makes a reset of an idle stream a
//! connection error, and h2 answers it so: GOAWAY PROTOCOL_ERROR, which fails every other call on
//! the connection ("GOAWAY received"). The C++ SDK's close, which cancels a stream it has just
//! started, met it in about one run in twelve. gRPC's own server ignores such a reset, as grpc.aio
//! did when it served this port; so does the edge now. Nothing else is changed: every other byte
//! reaches h2 as it came, in order.

use std::io;
use std::pin::Pin;
use std::task::{Context, Poll};

use bytes::BytesMut;
use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};

const PREFACE_BYTES: usize = 24; // "PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n" (RFC 9113 section 3.4)
const HEADER_BYTES: usize = 9; // a frame's length (24 bits), type, flags, stream id (31 bits)
const HEADERS: u8 = 0x1;
const RST_STREAM: u8 = 0x3;
const READ_CHUNK_BYTES: usize = 16 * 1024; // read from the socket at most this much at a time

/// Where the reader stands in the client's byte stream.
#[derive(Clone, Copy, Debug, PartialEq)]
enum At {
    Preface(usize), // bytes of the preface still to pass
    Header,         // the next frame's header
    Payload { left: usize, dropped: bool },
}

/// A client connection whose reads leave out RST_STREAM frames on idle client streams.
pub struct IdleResetsDropped<S> {
    inner: S,
    read: BytesMut,  // read from the socket, not yet passed on or dropped
    ready: BytesMut, // passed on, not yet taken by h2
    at: At,
    chunk: Box<[u8]>,    // one read from the socket
    highest_opened: u32, // the highest stream id the client's HEADERS opened
    eof: bool,
}

impl<S> IdleResetsDropped<S> {
    pub fn new(inner: S) -> Self {
        Self {
            inner,
            read: BytesMut::new(),
            ready: BytesMut::new(),
            at: At::Preface(PREFACE_BYTES),
            chunk: vec![0; READ_CHUNK_BYTES].into_boxed_slice(),
            highest_opened: 0,
            eof: false,
        }
    }

    /// Moves what `read` holds to `ready` frame by frame, leaving out resets of idle streams; a
    /// frame header split across reads waits for its last byte.
    fn sort(&mut self) {
        loop {
            let (left, dropped) = match self.at {
                At::Preface(left) => (left, false),
                At::Payload { left, dropped } => (left, dropped),
                At::Header => {
                    if self.read.len() < HEADER_BYTES {
                        return;
                    }
                    let h = &self.read[..HEADER_BYTES];
                    let length =
                        usize::from(h[0]) << 16 | usize::from(h[1]) << 8 | usize::from(h[2]);
                    let stream = u32::from_be_bytes([h[5], h[6], h[7], h[8]]) & 0x7fff_ffff;
                    if h[3] == HEADERS {
                        self.highest_opened = self.highest_opened.max(stream);
                    }
                    // a client's streams are odd; an id past every one it opened is idle
                    let dropped =
                        h[3] == RST_STREAM && stream % 2 == 1 && stream > self.highest_opened;
                    let header = self.read.split_to(HEADER_BYTES);
                    if !dropped {
                        self.ready.extend_from_slice(&header);
                    }
                    self.at = At::Payload {
                        left: length,
                        dropped,
                    };
                    continue;
                }
            };
            if left == 0 {
                self.at = At::Header;
                continue;
            }
            let n = left.min(self.read.len());
            if n == 0 {
                return;
            }
            let passed = self.read.split_to(n);
            if !dropped {
                self.ready.extend_from_slice(&passed);
            }
            self.at = match self.at {
                At::Preface(_) => At::Preface(left - n),
                _ => At::Payload {
                    left: left - n,
                    dropped,
                },
            };
        }
    }
}

impl<S: AsyncRead + Unpin> AsyncRead for IdleResetsDropped<S> {
    fn poll_read(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<io::Result<()>> {
        let this = self.get_mut();
        loop {
            if !this.ready.is_empty() {
                let n = this.ready.len().min(buf.remaining());
                buf.put_slice(&this.ready.split_to(n));
                return Poll::Ready(Ok(()));
            }
            if this.eof {
                // a frame cut short by the close: h2 sees the bytes there were, and then the end
                this.ready = std::mem::take(&mut this.read);
                if this.ready.is_empty() {
                    return Poll::Ready(Ok(()));
                }
                continue;
            }
            let mut chunk_buf = ReadBuf::new(&mut this.chunk);
            match Pin::new(&mut this.inner).poll_read(cx, &mut chunk_buf) {
                Poll::Pending => return Poll::Pending,
                Poll::Ready(Err(e)) => return Poll::Ready(Err(e)),
                Poll::Ready(Ok(())) => {
                    if chunk_buf.filled().is_empty() {
                        this.eof = true;
                    } else {
                        this.read.extend_from_slice(chunk_buf.filled());
                        this.sort();
                    }
                }
            }
        }
    }
}

impl<S: AsyncWrite + Unpin> AsyncWrite for IdleResetsDropped<S> {
    fn poll_write(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        data: &[u8],
    ) -> Poll<io::Result<usize>> {
        Pin::new(&mut self.get_mut().inner).poll_write(cx, data)
    }

    fn poll_write_vectored(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        bufs: &[io::IoSlice<'_>],
    ) -> Poll<io::Result<usize>> {
        Pin::new(&mut self.get_mut().inner).poll_write_vectored(cx, bufs)
    }

    fn is_write_vectored(&self) -> bool {
        self.inner.is_write_vectored()
    }

    fn poll_flush(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.get_mut().inner).poll_flush(cx)
    }

    fn poll_shutdown(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.get_mut().inner).poll_shutdown(cx)
    }
}

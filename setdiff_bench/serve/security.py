"""Credentials of ``setdiff-bench serve`` and its clients: TLS files, the bearer token, the bind rule.

No grpc import here, so the CLI can validate options (and refuse a bad bind) before loading grpc or a
model.  Secrets never reach a message, a log line or a ``repr``: errors name the file or the variable,
never the token.

* **TLS**: the server reads a PEM certificate chain and key (``--tls-cert``, ``--tls-key``); with
  ``--tls-client-ca`` it also requires every client to present a certificate signed by that CA
  (mutual TLS).  A client trusts ``--tls-ca`` (the CA that signed the server certificate).
* **Bearer token**: read from a file (``--token-file``) or the environment variable
  :data:`TOKEN_ENV` -- never from a command-line argument, which ``ps`` shows to every user.  A token
  file is re-read when it changes, so replacing it rotates the token: the old one is then expired
  and refused.
* **Bind rule**: a non-loopback ``--host`` needs TLS *and* a token, unless ``--insecure``.
"""

from __future__ import annotations

import hmac
import ipaddress
import os
import threading
from dataclasses import dataclass, field
from pathlib import Path

from setdiff_bench.errors import UsageError

#: Environment variable holding the bearer token (server and client) when no token file is given.
TOKEN_ENV = "SETDIFF_SERVE_TOKEN"
#: Shortest token accepted (characters): a guessable token is no authentication.
MIN_TOKEN_CHARS = 16
#: Largest PEM or token file read (bytes).
MAX_SECRET_FILE_BYTES = 1 << 20


def is_loopback(host: str) -> bool:
    """Whether ``host`` (an IP literal, ``[v6]`` or ``localhost``) only accepts connections from this machine."""
    name = host.strip().strip("[]").lower()
    if name == "localhost":
        return True
    try:
        return ipaddress.ip_address(name).is_loopback
    except ValueError:  # another host name: it may resolve to any interface
        return False


def _read_secret_file(path: Path, option: str) -> bytes:
    try:
        size = path.stat().st_size
        if size > MAX_SECRET_FILE_BYTES:
            raise UsageError(f"{size} bytes; at most {MAX_SECRET_FILE_BYTES} expected", path)
        return path.read_bytes()
    except FileNotFoundError:
        raise UsageError(f"not found (given by {option})", path) from None
    except IsADirectoryError:
        raise UsageError(f"is a folder, not a file (given by {option})", path) from None
    except PermissionError:
        raise UsageError(f"not readable (given by {option})", path) from None


def read_pem(path: str | os.PathLike[str], option: str, kind: str) -> bytes:
    """A PEM file's bytes, checked to hold a ``kind`` block (``CERTIFICATE`` or ``PRIVATE KEY``)."""
    data = _read_secret_file(Path(path), option)
    if b"-----BEGIN " not in data or kind.encode() not in data:
        raise UsageError(f"not a PEM file with a {kind} (given by {option})", path)
    return data


def _check_token(token: str, where: str) -> str:
    token = token.strip()
    if not token:
        raise UsageError("the bearer token is empty", where)
    if len(token) < MIN_TOKEN_CHARS or any(c.isspace() or not c.isprintable() for c in token):
        raise UsageError(
            f"the bearer token must be at least {MIN_TOKEN_CHARS} printable characters without spaces",
            where,
        )
    return token


class TokenSource:
    """The bearer token, from a file (re-read when it changes: rotation) or an environment variable.

    :meth:`accepts` compares in constant time.  ``repr`` never shows the token.
    """

    def __init__(self, *, file: str | os.PathLike[str] | None = None, env: str | None = None) -> None:
        if (file is None) == (env is None):
            raise ValueError("give exactly one of file= and env=")
        self.file = None if file is None else Path(file)
        self.env = env
        self._lock = threading.Lock()
        self._stamp: tuple[int, int, int] | None = None
        if self.file is not None:
            self._token = self._load_file()
        else:
            value = os.environ.get(env or "")
            if value is None:
                raise UsageError("not set", f"${env}")
            self._token = _check_token(value, f"${env}")

    def __repr__(self) -> str:
        return f"TokenSource(file={self.file!s})" if self.file else f"TokenSource(env={self.env})"

    def _load_file(self) -> str:
        assert self.file is not None
        stat = self.file.stat() if self.file.exists() else None
        data = _read_secret_file(self.file, "--token-file")
        self._stamp = None if stat is None else (stat.st_ino, stat.st_mtime_ns, stat.st_size)
        try:
            text = data.decode("utf-8")
        except UnicodeDecodeError:
            raise UsageError("the token file is not UTF-8 text", self.file) from None
        return _check_token(text, str(self.file))

    def current(self) -> str:
        """The token now in force (a changed file is re-read; an unreadable one keeps the last token)."""
        if self.file is None:
            return self._token
        with self._lock:
            try:
                stat = self.file.stat()
                stamp = (stat.st_ino, stat.st_mtime_ns, stat.st_size)
                if stamp != self._stamp:
                    self._token = self._load_file()
            except (OSError, UsageError):
                pass  # mid-rotation (file briefly absent or empty): keep the last good token
            return self._token

    def accepts(self, given: str) -> bool:
        """Whether ``given`` is the token in force (constant-time comparison)."""
        return hmac.compare_digest(given.encode("utf-8", "replace"), self.current().encode())


def token_source(token_file: str | os.PathLike[str] | None) -> TokenSource | None:
    """The token from ``token_file``, else from ``$SETDIFF_SERVE_TOKEN`` if set, else ``None`` (no token)."""
    if token_file is not None:
        return TokenSource(file=token_file)
    if os.environ.get(TOKEN_ENV) is not None:
        return TokenSource(env=TOKEN_ENV)
    return None


@dataclass(frozen=True)
class ServerTls:
    """PEM bytes of the server's certificate chain and key, and of the client CA (mutual TLS) if any."""

    cert_chain: bytes = field(repr=False)
    private_key: bytes = field(repr=False)
    client_ca: bytes | None = field(default=None, repr=False)

    @classmethod
    def from_files(
        cls,
        cert: str | os.PathLike[str] | None,
        key: str | os.PathLike[str] | None,
        client_ca: str | os.PathLike[str] | None = None,
    ) -> ServerTls | None:
        """Read ``--tls-cert`` / ``--tls-key`` (both or neither) and ``--tls-client-ca`` (needs them)."""
        if cert is None and key is None:
            if client_ca is not None:
                raise UsageError("mutual TLS needs --tls-cert and --tls-key too", "--tls-client-ca")
            return None
        if cert is None or key is None:
            raise UsageError(
                "give both --tls-cert and --tls-key", "--tls-cert" if cert is None else "--tls-key"
            )
        return cls(
            read_pem(cert, "--tls-cert", "CERTIFICATE"),
            read_pem(key, "--tls-key", "PRIVATE KEY"),
            None if client_ca is None else read_pem(client_ca, "--tls-client-ca", "CERTIFICATE"),
        )


def check_bind(host: str, tls: ServerTls | None, token: TokenSource | None, insecure: bool) -> None:
    """Refuse a non-loopback ``host`` without TLS and a token (unless ``insecure``), in one line.

    Raises:
        UsageError: the address would expose an unauthenticated or unencrypted service.
    """
    if is_loopback(host) or insecure or (tls is not None and token is not None):
        return
    missing = " and ".join(
        what
        for what, absent in (
            ("TLS (--tls-cert, --tls-key)", tls is None),
            (f"a token (--token-file or ${TOKEN_ENV})", token is None),
        )
        if absent
    )
    raise UsageError(
        f"{host} is not a loopback address: anyone who reaches it could use the service; "
        f"give {missing}, or --insecure to serve it anyway",
        "--host",
    )

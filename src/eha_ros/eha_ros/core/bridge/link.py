"""ADS link to the PLC through pyads: symbol check at connect, one sum request per cycle.

``connect()`` opens the AMS route, looks every mapped symbol up in the PLC's symbol table
(ADSIGRP_SYM_INFOBYNAMEEX: index group/offset, size, data type) and refuses a map whose
symbols are unknown or have another type (:class:`SymbolError`, one line). ``cycle(write)``
then writes the command block and reads the state block in ONE request, ADS sum read/write
(ADSIGRP_SUMUP_READWRITE, 0xF082), or in two (sum write 0xF081 then sum read 0xF080) with
``sum_mode='separate'``. The buffers are built once; a cycle is one call into AdsLib.
Network trouble raises :class:`LinkError`; the caller decides when the link counts as lost.
"""
from __future__ import annotations

import ctypes
import struct

from ..config.params import ParamError
from .symbols import PLC_TYPES, SymbolMap

ADSIGRP_SYM_INFOBYNAMEEX = 0xF009
ADSIGRP_SUMUP_READ = 0xF080
ADSIGRP_SUMUP_WRITE = 0xF081
ADSIGRP_SUMUP_READWRITE = 0xF082
ADSERR_SYMBOLNOTFOUND = 0x710          # 1808
ADS_TYPE_NAMES = {v[1]: k for k, v in PLC_TYPES.items()}


def quiet_adslib(level: int = 2):
    """AdsLib logs to stderr from its own threads ('Info: connection closed by remote'):
    keep warnings and errors only (Logger::logLevel: 0 verbose, 1 info, 2 warn, 3 error)."""
    try:
        from pyads.pyads_ex import _adsDLL
        ctypes.c_size_t.in_dll(_adsDLL, '_ZN6Logger8logLevelE').value = level
    except (ImportError, ValueError, AttributeError):  # pragma: no cover - other AdsLib build
        pass


class LinkError(Exception):
    """The PLC did not answer (timeout, refused, closed) or answered with an ADS error."""

    def __init__(self, message: str, code: int = 0):
        super().__init__(message)
        self.code = code


class SymbolError(ParamError):
    """The symbol map does not match the PLC (unknown symbol, other type); one line."""


def ads_error_text(code: int) -> str:
    try:
        from pyads.errorcodes import ERROR_CODES
        return f'ADS error {code} ({ERROR_CODES.get(code, "unknown")})'
    except ImportError:  # pragma: no cover
        return f'ADS error {code}'


class AdsLink:
    """One route to one PLC runtime (AMS net id + port) at ``host:tcp_port``."""

    log_level = 2            # AdsLib's own stderr lines (quiet_adslib); 4: none

    def __init__(self, smap: SymbolMap, ams_net_id: str, ams_port: int, host: str,
                 tcp_port: int, timeout: float, sum_mode: str = 'readwrite'):
        self.smap = smap
        self.ams_net_id, self.ams_port = ams_net_id, int(ams_port)
        self.host, self.tcp_port = host, int(tcp_port)
        self.timeout_ms = max(1, int(round(timeout * 1000)))
        self.sum_mode = sum_mode
        self.conn = None
        self.infos = {}
        self.requests = 0

    @property
    def address(self) -> str:
        return f'{self.ams_net_id}:{self.ams_port} at {self.host}:{self.tcp_port}'

    # ------------------------------------------------------------ connect
    def connect(self) -> dict:
        """Open the route, check every symbol, build the cyclic request; returns the PLC's
        current command block {role: SI value} (so the bridge starts from what is there)."""
        import pyads
        quiet_adslib(self.log_level)
        self.close()
        conn = pyads.Connection(self.ams_net_id, self.ams_port, f'{self.host}:{self.tcp_port}')
        try:
            conn.open()
            conn.set_timeout(self.timeout_ms)
        except pyads.ADSError as err:
            try:
                conn.close()
            except Exception:
                pass
            raise LinkError(f'cannot open ADS route to {self.address}: '
                            f'{ads_error_text(err.err_code)}', err.err_code) from None
        self.conn = conn
        try:
            self.infos = {s.role: self._check(s) for s in self.smap.read + self.smap.write}
            self._build()
            raw = self._sum_read([self.infos[s.role] for s in self.smap.write],
                                 self.smap.write_fmt)
        except BaseException:
            self.close()
            raise
        return {s.role: s.to_si(v) for s, v in zip(self.smap.write, raw)}

    def _check(self, sym):
        """Symbol table entry of one symbol: (index group, index offset, size); type checked."""
        import pyads
        from pyads.pyads_ex import adsGetSymbolInfo
        try:
            info = adsGetSymbolInfo(self.conn._port, self.conn._adr, sym.name)
        except pyads.ADSError as err:
            if err.err_code == ADSERR_SYMBOLNOTFOUND:
                raise SymbolError(f'symbol map {self.smap.path}: symbols.{sym.role}.symbol = '
                                  f'{sym.name!r}: unknown symbol on the PLC {self.address} '
                                  f'(ADS error 1808): expected a symbol of its symbol table'
                                  ) from None
            raise LinkError(f'symbol {sym.name}: {ads_error_text(err.err_code)}',
                            err.err_code) from None
        plc_type = info.symbol_type.strip().upper() or ADS_TYPE_NAMES.get(info.dataType, '?')
        if info.dataType != sym.ads_type or info.size != sym.size:
            raise SymbolError(f'symbol map {self.smap.path}: symbols.{sym.role}.type = '
                              f'{sym.plc_type}: wrong type: the PLC declares {sym.name} as '
                              f'{plc_type} ({info.size} bytes): expected the map to say '
                              f'{plc_type}')
        return int(info.iGroup), int(info.iOffs), int(info.size)

    def _build(self):
        """Preallocate the request and response buffers of the cycle."""
        rd = [self.infos[s.role] for s in self.smap.read]
        wr = [self.infos[s.role] for s in self.smap.write]
        self._read_hdr = b''.join(struct.pack('<III', *i) for i in rd)
        self._wr_hdr = b''.join(struct.pack('<III', *i) for i in wr)
        self._rw_hdr = b''.join(struct.pack('<IIII', g, o, 0, n) for g, o, n in wr) + \
            b''.join(struct.pack('<IIII', g, o, n, 0) for g, o, n in rd)
        n_rw = len(wr) + len(rd)
        self._n = (len(wr), len(rd), n_rw)
        self._rw_resp = ctypes.create_string_buffer(8 * n_rw + self.smap.read_size)
        self._r_resp = ctypes.create_string_buffer(4 * len(rd) + self.smap.read_size)
        self._w_resp = ctypes.create_string_buffer(4 * len(wr))
        self._read_struct = struct.Struct(self.smap.read_fmt)
        self._write_struct = struct.Struct(self.smap.write_fmt)
        self._bytes_read = ctypes.c_uint32()

    def close(self):
        if self.conn is not None:
            try:
                self.conn.close()
            except Exception:
                pass
            self.conn = None

    # ------------------------------------------------------------ cycle
    def cycle(self, write_raw: tuple) -> tuple:
        """Write the command block (raw PLC values, struct order) and read the state block
        (raw values, struct order) in one sum request (two with sum_mode='separate')."""
        if self.conn is None:
            raise LinkError('not connected')
        data = self._write_struct.pack(*write_raw)
        n_w, n_r, n = self._n
        if self.sum_mode == 'readwrite':
            self._request(ADSIGRP_SUMUP_READWRITE, n, self._rw_resp, self._rw_hdr + data)
            resp = self._rw_resp.raw
            self._results(resp, n, 8)
            return self._read_struct.unpack_from(resp, 8 * n)
        self._request(ADSIGRP_SUMUP_WRITE, n_w, self._w_resp, self._wr_hdr + data)
        self._results(self._w_resp.raw, n_w, 4)
        self._request(ADSIGRP_SUMUP_READ, n_r, self._r_resp, self._read_hdr)
        resp = self._r_resp.raw
        self._results(resp, n_r, 4)
        return self._read_struct.unpack_from(resp, 4 * n_r)

    def read_block(self) -> tuple:
        """Read the state block alone (raw values), e.g. to refresh without commanding."""
        return self._sum_read([self.infos[s.role] for s in self.smap.read], self.smap.read_fmt)

    def _sum_read(self, infos, fmt) -> tuple:
        hdr = b''.join(struct.pack('<III', *i) for i in infos)
        resp = ctypes.create_string_buffer(4 * len(infos) + struct.calcsize(fmt))
        self._request(ADSIGRP_SUMUP_READ, len(infos), resp, hdr)
        self._results(resp.raw, len(infos), 4)
        return struct.unpack_from(fmt, resp.raw, 4 * len(infos))

    def _request(self, group: int, offset: int, resp, payload: bytes):
        from pyads.pyads_ex import _adsDLL
        self.requests += 1
        adr = self.conn._adr.amsAddrStruct()
        err = _adsDLL.AdsSyncReadWriteReqEx2(
            ctypes.c_long(self.conn._port), ctypes.pointer(adr), ctypes.c_uint32(group),
            ctypes.c_uint32(offset), ctypes.c_uint32(len(resp)), resp,
            ctypes.c_uint32(len(payload)), ctypes.c_char_p(payload),
            ctypes.pointer(self._bytes_read))
        if err:
            raise LinkError(f'{ads_error_text(err)} from {self.address}', err)

    def _results(self, resp: bytes, n: int, stride: int):
        for i in range(n):
            code = struct.unpack_from('<I', resp, stride * i)[0]
            if code:
                raise LinkError(f'sum request item {i}: {ads_error_text(code)}', code)

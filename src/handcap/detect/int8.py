"""The corner network in 8-bit integers: the same corners, faster on the CPU.

The corner network's convolutions are most of the detector's time on a whole frame. Quantised to 8-bit integers
(weights per output channel, activations per tensor: PyTorch's eager-mode static quantisation, run by its oneDNN
engine) the network took 0.35 s instead of 0.46 s on the 5 MP frame of ``benchmarks/detect.py`` (2 threads), and
the whole detector 0.65 s instead of 0.89 s, with the same corners: on its 20 held-out scenes, refined, recall
92.5 against 92.2 %, median error 0.152 px both, RMS 0.327 against 0.323 px; on 100 held-out hand scenes 71.8
against 71.7 % of the visible tags read right, 0.24 % of those read wrong both. PyTorch's default x86 engine
(FBGEMM) gave no speed-up on the same machine.

Static quantisation needs the range of every activation. :func:`activation_ranges` measures them once on
rendered scenes (a histogram per activation, PyTorch's choice of the range that loses least) and they are saved
with the weights (``CornerNet.ranges``, ``tools/corner_ranges.py``); :func:`int8_corner_net` builds the
integer network from them. Without ranges in the weights, or where PyTorch has no oneDNN engine (its ARM
builds), :func:`int8_corner_net` gives the float network back unchanged.

The corner refiner (:mod:`handcap.detect.refine`) has an integer twin too (:func:`int8_refiner`): on a hand's
region it is most of the detector's time, a few thousand 17 x 17 crops (each candidate in its eight views). Its
convolutions run in integers and its two dense layers, which give the sub-pixel offset, in floats, from the
ranges :func:`refiner_ranges` measures on the crops the detector gives it. Measured with ``benchmarks/detect.py``
(2026-11-30, the shipped networks and ranges, 2 threads): on its 20 held-out scenes recall 92.5 % both, median
error 0.154 against 0.152 px, RMS 0.333 against 0.327 px; the refined corners of its hand region in 0.125 s
against 0.191 s, the whole detector there in a median of 0.237 s. Tried while building this, with ranges from
10 hand scenes: the dense layers in integers too were no faster and placed corners worse (median 0.156 px, RMS
0.334 px, against 0.153 and 0.329 px with them in floats); the first convolution in floats was slower.
"""

from __future__ import annotations

import contextlib
import copy
import warnings

import numpy as np
import torch
from torch import nn

try:  # PyTorch deprecates its eager-mode quantisation (still there in 2.13); without it, the float network
    import torch.ao.quantization as tq
    from torch.ao.nn.quantized import FloatFunctional
except ImportError:  # pragma: no cover - a PyTorch without it
    tq = FloatFunctional = None

from handcap.core.errors import HandcapError
from handcap.detect.corners import MAX_OFFSET, CornerNet, detect_corners, normalise
from handcap.detect.refine import CANDIDATES, MAX_SHIFT, CornerRefiner, crops_at, turned_crops

#: The quantised engine the integer network is built for.
ENGINE = "onednn"


class Int8CornerNet(nn.Module):
    """A :class:`~handcap.detect.corners.CornerNet`'s layers laid out for quantisation (same outputs in floats).

    Parameters
    ----------
    net : CornerNet
        Copied; the copy's convolutions and ReLUs are fused and its residual sums made quantisable.
    """

    def __init__(self, net: CornerNet):
        super().__init__()
        self.width, self.stem_width, self.dilations = net.width, net.stem_width, net.dilations
        self.quant, self.dequant = tq.QuantStub(), tq.DeQuantStub()
        self.stem = nn.Sequential(copy.deepcopy(net.stem), nn.ReLU())
        self.down = nn.Sequential(copy.deepcopy(net.down), nn.ReLU())
        self.body = nn.ModuleList([nn.Sequential(copy.deepcopy(conv), nn.ReLU()) for conv in net.body])
        self.sums = nn.ModuleList([FloatFunctional() for _ in net.body])
        self.head = copy.deepcopy(net.head)
        for block in (self.stem, self.down, *self.body):
            tq.fuse_modules(block, ["0", "1"], inplace=True)
        self.__dict__["float_net"] = net  # not a submodule: what it is pickled as

    def __reduce__(self):
        """Pickled as its float network, and built again from it (PyTorch's converted layers do not pickle), so a
        :class:`~handcap.detect.pipeline.Detector` travels to worker processes."""
        return int8_corner_net, (self.float_net,)

    def forward(self, image: torch.Tensor) -> torch.Tensor:
        """As :meth:`CornerNet.forward`: (B, 1, H, W) normalised grey levels -> (B, 3, H / 2, W / 2)."""
        x = self.down(self.stem(self.quant(image)))
        for conv, add in zip(self.body, self.sums):
            x = add.add(conv(x), x)
        out = self.dequant(self.head(x))
        return torch.cat([out[:, :1], MAX_OFFSET * torch.tanh(out[:, 1:])], dim=1)

    def flops_per_pixel(self) -> float:
        """As :meth:`CornerNet.flops_per_pixel` (integer operations)."""
        return CornerNet.flops_per_pixel(self)

    def reach(self) -> int:
        """As :meth:`CornerNet.reach`."""
        return CornerNet.reach(self)

    def observers(self) -> list:
        """The activation observers of a prepared network, in the order of ``CornerNet.ranges``."""
        layers = [self.quant, self.stem[0], self.down[0], *(b[0] for b in self.body), *self.sums, self.head]
        return [layer.activation_post_process for layer in layers]


class Int8Refiner(nn.Module):
    """A :class:`~handcap.detect.refine.CornerRefiner`'s layers laid out for quantisation: its convolutions in
    integers, its dense head in floats (same outputs).

    Parameters
    ----------
    net : CornerRefiner
        Copied; the copy's convolutions and ReLUs are fused.
    """

    def __init__(self, net: CornerRefiner):
        super().__init__()
        self.width = net.width
        self.quant, self.dequant = tq.QuantStub(), tq.DeQuantStub()
        self.features = copy.deepcopy(net.features)
        self.head = copy.deepcopy(net.head)
        self.head.qconfig = None  # floats: the offsets' last fractions of a pixel
        tq.fuse_modules(self.features, [[str(k), str(k + 1)] for k in range(0, len(self.features), 2)], inplace=True)
        self.__dict__["float_net"] = net  # not a submodule: what it is pickled as

    def __reduce__(self):
        """Pickled as its float network, and built again from it (as :meth:`Int8CornerNet.__reduce__`)."""
        return int8_refiner, (self.float_net,)

    def forward(self, crops: torch.Tensor) -> torch.Tensor:
        """As :meth:`CornerRefiner.forward`: (N, 1, 17, 17) normalised crops -> (N, 3)."""
        out = self.head(self.dequant(self.features(self.quant(crops))))
        return torch.cat([out[:, :1], MAX_SHIFT * torch.tanh(out[:, 1:])], dim=1)

    def observers(self) -> list:
        """The activation observers of a prepared network, in the order of ``CornerRefiner.ranges``."""
        layers = [self.quant, *(self.features[k] for k in range(0, len(self.features), 2))]
        return [layer.activation_post_process for layer in layers]


#: Each network's integer twin.
TWINS = {CornerNet: Int8CornerNet, CornerRefiner: Int8Refiner}


@contextlib.contextmanager
def _engine(name: str):
    """PyTorch's quantised engine set to ``name`` (restored afterwards), its deprecation warnings silenced."""
    before = torch.backends.quantized.engine
    torch.backends.quantized.engine = name
    try:
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", category=DeprecationWarning, module="torch")
            warnings.filterwarnings("ignore", "torch.quantize_per", UserWarning)
            warnings.filterwarnings("ignore", ".*torch.ao.quantization", DeprecationWarning)
            yield
    finally:
        torch.backends.quantized.engine = before


def available() -> bool:
    """Whether this PyTorch can build the integer network (eager-mode quantisation and the oneDNN engine)."""
    return tq is not None and ENGINE in torch.backends.quantized.supported_engines


def _prepared(net: CornerNet | CornerRefiner, activation) -> Int8CornerNet | Int8Refiner:
    with _engine(ENGINE):
        model = TWINS[type(net)](net).eval()
        model.qconfig = tq.QConfig(activation=activation, weight=tq.default_per_channel_weight_observer)
        tq.prepare(model, inplace=True)
    return model


def activation_ranges(net: CornerNet, images) -> np.ndarray:
    """The range of each of the network's activations over ``images``, for its integer twin.

    Parameters
    ----------
    net : CornerNet
    images : sequence of ndarray (H, W)
        Grey images (uint8, or floats 0..1) like those it will see: rendered scenes.

    Returns
    -------
    ndarray (P, 2)
        Least and greatest value of each activation (:meth:`Int8CornerNet.observers`' order), as the
        histogram observers choose them (outliers clipped where that loses less).
    """
    if not available():
        raise HandcapError(f"this PyTorch cannot quantise ({ENGINE} engine): the ranges cannot be measured here")
    model = _prepared(net, tq.HistogramObserver.with_args(reduce_range=False))
    with torch.inference_mode():
        for image in images:
            img = normalise(np.asarray(image))
            h, w = img.shape[0] // 2 * 2, img.shape[1] // 2 * 2
            model(torch.from_numpy(np.ascontiguousarray(img[:h, :w]))[None, None])
    return _ranges(model)


def refiner_ranges(net: CornerRefiner, corner_net, images, batch: int = 4096) -> np.ndarray:
    """The range of each of the refiner's integer activations over the crops the detector gives it in ``images``:
    the corner network's candidates (down to :data:`~handcap.detect.refine.CANDIDATES`), in all eight views.

    Parameters
    ----------
    net : CornerRefiner
    corner_net : CornerNet or Int8CornerNet
        The network whose candidates it refines.
    images : sequence of ndarray (H, W)
        Grey images like those it will see: rendered scenes.
    batch : int
        Crops per call.

    Returns
    -------
    ndarray (P, 2)
        As :func:`activation_ranges` (:meth:`Int8Refiner.observers`' order).
    """
    if not available():
        raise HandcapError(f"this PyTorch cannot quantise ({ENGINE} engine): the ranges cannot be measured here")
    model, seen = _prepared(net, tq.HistogramObserver.with_args(reduce_range=False)), 0
    with torch.inference_mode():
        for image in images:
            xy, _ = detect_corners(corner_net, image, threshold=CANDIDATES)
            if len(xy) == 0:
                continue
            crops = torch.from_numpy(turned_crops(crops_at(image, np.rint(xy).astype(int)), range(8)))[:, None]
            for k in range(0, len(crops), batch):
                model(crops[k:k + batch])
            seen += len(xy)
    if seen == 0:
        raise HandcapError("the corner network found no candidate in these images: no crops to measure the "
                           "refiner's ranges on")
    return _ranges(model)


def _ranges(model) -> np.ndarray:
    """(P, 2) ranges of a prepared twin's observers."""
    ranges = []
    for observer in model.observers():
        scale, zero = (float(v) for v in observer.calculate_qparams())
        ranges.append(((observer.quant_min - zero) * scale, (observer.quant_max - zero) * scale))
    return np.array(ranges)


def int8_corner_net(net: CornerNet) -> nn.Module:
    """The integer twin of a corner network whose weights carry activation ranges, else the network itself.

    Parameters
    ----------
    net : CornerNet
        With ``ranges`` (:func:`activation_ranges`), as the shipped weights are.

    Returns
    -------
    Int8CornerNet or CornerNet
        The integer network (converted, for inference only), or ``net`` where it has no ranges or PyTorch no
        oneDNN engine.
    """
    return _twin(net, "corner network")


def int8_refiner(net: CornerRefiner) -> nn.Module:
    """The integer twin of a corner refiner whose weights carry activation ranges, else the refiner itself.

    Parameters
    ----------
    net : CornerRefiner
        With ``ranges`` (:func:`refiner_ranges`), as the shipped weights are.

    Returns
    -------
    Int8Refiner or CornerRefiner
        The integer refiner (converted, for inference only), or ``net`` where it has no ranges or PyTorch no
        oneDNN engine.
    """
    return _twin(net, "corner refiner")


def _twin(net, what: str) -> nn.Module:
    ranges = getattr(net, "ranges", None)
    if ranges is None or not available():
        return net
    model = _prepared(net, tq.MinMaxObserver.with_args(dtype=torch.quint8, reduce_range=False))
    observers = model.observers()
    if np.shape(ranges) != (len(observers), 2):
        raise HandcapError(f"{what}: {np.shape(ranges)} activation ranges for {len(observers)} activations")
    for observer, (lo, hi) in zip(observers, np.asarray(ranges, dtype=np.float32)):
        observer(torch.tensor([lo, hi]))
    try:
        with _engine(ENGINE):
            tq.convert(model, inplace=True)
    except (RuntimeError, AttributeError):  # a PyTorch that lost them: the float network
        return net
    return model.eval()

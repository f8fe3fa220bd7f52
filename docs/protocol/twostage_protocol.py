"""The twostage simulator protocol, versions 1 and 2: serve a Python
simulator to `twostage` over standard input and output (docs/protocol.md).

    from twostage_protocol import serve

    def simulate(theta, seed, index):
        rng = random.Random(seed * 1_000_003 + index)   # or numpy's default_rng([seed, index])
        ...
        return inputs, outputs          # N rows of n_u values, N rows of n_y values

    serve(simulate)

A simulator that vectorizes gives `serve(batch=f)` instead, with
f(thetas, seeds, indices) -> (inputs, outputs) of shapes [b][N][n_u] and
[b][N][n_y]. Pure Python: no package is needed.

Version 2 (the model file says `protocol = 2` under [source]) calls the
function with two more keywords: `noiseless` (True: leave every noise out,
return the model's own response) and `input` (None, or the N rows of n_u
values to apply instead of the simulator's own input; return them as the
inputs). A version 1 simulator never sees them. A batch function's
`input` is N rows shared by every experiment of the batch (`given`), or,
when each experiment has its own (`each`: an input design twostage draws
per experiment), a list of them, [b][N][n_u]: `np.ndim(input) == 3`.
"""

import inspect
import sys

VERSIONS = (1, 2)


class Shape:
    """What the greeting announced: parameters, inputs, outputs, samples."""

    def __init__(self, q, n_u, n_y, n):
        self.q, self.n_u, self.n_y, self.n = q, n_u, n_y, n

    def samples(self, n):
        """The same shape for records of n samples."""
        return Shape(self.q, self.n_u, self.n_y, n)


def _record(index, inputs, outputs, shape):
    """The answer lines of one experiment, checked against the shape."""
    # Plain lists of Python floats first: a numpy array's `tolist` is many
    # times faster than indexing it sample by sample.
    inputs = inputs.tolist() if hasattr(inputs, "tolist") else inputs
    outputs = outputs.tolist() if hasattr(outputs, "tolist") else outputs
    if len(outputs) != shape.n or (shape.n_u and len(inputs) != shape.n):
        raise ValueError(
            "the record has %d samples, the request asked for %d (a given input of %d samples: "
            "simulate its length)" % (len(outputs), shape.n, shape.n)
        )
    lines = ["record %d" % index]
    for k in range(shape.n):
        row = list(inputs[k]) if shape.n_u else []
        row += outputs[k]
        if len(row) != shape.n_u + shape.n_y:
            raise ValueError(
                "sample %d has %d values, the model has %d input(s) and %d output(s)"
                % (k, len(row), shape.n_u, shape.n_y)
            )
        lines.append(" ".join(map(repr, map(float, row))))
    return lines


def _one_line(text):
    return " ".join(str(text).split()) or "failed"


def _require_keywords(function):
    """Protocol 2 hands every call `noiseless` and `input`: say so at once,
    not as a failure of every experiment."""
    try:
        parameters = inspect.signature(function).parameters
    except (TypeError, ValueError):  # a builtin or C function: trust it
        return
    if any(p.kind == p.VAR_KEYWORD for p in parameters.values()):
        return
    missing = [k for k in ("noiseless", "input") if k not in parameters]
    if missing:
        sys.stderr.write(
            "protocol 2 calls %s with the two keywords noiseless and input; it lacks %s: "
            "define it as def %s(..., noiseless=False, input=None) (docs/protocol.md)\n"
            % (function.__name__, " and ".join(missing), function.__name__)
        )
        sys.exit(2)


def serve(simulate=None, batch=None, stdin=None, stdout=None):
    """Answer requests until `quit` or the end of input."""
    if (simulate is None) == (batch is None):
        raise TypeError("give simulate= (one experiment) or batch= (many at once)")
    stdin = stdin or sys.stdin
    stdout = stdout or sys.stdout
    greeting = stdin.readline().split()
    if len(greeting) != 6 or greeting[0] != "twostage" or int(greeting[1]) not in VERSIONS:
        sys.stderr.write("not a twostage greeting of version 1 or 2: %r\n" % (greeting,))
        sys.exit(2)
    version = int(greeting[1])
    if version >= 2:
        _require_keywords(simulate or batch)
    shape = Shape(*(int(v) for v in greeting[2:]))
    stdout.write("ready\n")
    stdout.flush()
    while True:
        line = stdin.readline()
        words = line.split()
        if not words or words[0] == "quit":
            return
        if words[0] != "batch" or len(words) not in ((2,) if version == 1 else (4, 5)):
            sys.stderr.write("unknown request %r\n" % line)
            sys.exit(2)
        # Version 2: `noise`/`noiseless`, then `own`, `given` (one input
        # after the experiments' lines) or `each` (every experiment's input
        # after its line); a fifth word is the records' length when it is
        # not the greeting's.
        asked = shape
        mode = "own"
        if version >= 2:
            if len(words) == 5:
                asked = shape.samples(int(words[4]))
            mode = words[3]
            if mode not in ("own", "given", "each"):
                sys.stderr.write("unknown input mode %r in request %r\n" % (mode, line))
                sys.exit(2)

        def read_input():
            return [[float(v) for v in stdin.readline().split()] for _ in range(asked.n)]

        jobs = []
        for _ in range(int(words[1])):
            values = stdin.readline().split()
            index, seed = int(values[0]), int(values[1])
            own_input = read_input() if mode == "each" else None
            jobs.append((index, seed, [float(v) for v in values[2:]], own_input))
        given = read_input() if mode == "given" else None
        noiseless = version >= 2 and words[2] == "noiseless"

        def conditions(job_input):
            if version < 2:
                return {}
            return {"noiseless": noiseless, "input": given if mode == "given" else job_input}

        out = []
        if batch is not None:
            try:
                every = [j[3] for j in jobs] if mode == "each" else None
                inputs, outputs = batch(
                    [j[2] for j in jobs], [j[1] for j in jobs], [j[0] for j in jobs],
                    **conditions(every)
                )
                for b, (index, _, _, _) in enumerate(jobs):
                    out += _record(index, inputs[b] if shape.n_u else None, outputs[b], asked)
            except Exception as e:  # every experiment of the batch fails
                out = ["error %d %s" % (j[0], _one_line(e)) for j in jobs]
        else:
            for index, seed, theta, own_input in jobs:
                try:
                    inputs, outputs = simulate(theta, seed, index, **conditions(own_input))
                    out += _record(index, inputs, outputs, asked)
                except Exception as e:  # this experiment fails, the others go on
                    out.append("error %d %s" % (index, _one_line(e)))
        stdout.write("\n".join(out) + "\n")
        stdout.flush()

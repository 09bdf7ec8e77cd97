"""Values passed to a compiled kernel by reference: one pointer where numba would pass hundreds.

numba passes a tuple flat: every array in it as its 7 to 11 machine words (meminfo, parent,
size, itemsize, data, shape, strides), each copied onto the stack at every call. The warm
contact steps take the scene's tables, the System, the contact buffers and their own
scratch (`models.stepper.SpatialWarm`, about 40 arrays): about 700 words a call, once a step.
On box_push_3d's push, perf put 6.7% of the step's time on the `push` instructions of
`models.rollout._contact_run`'s calls; passing those arguments by reference made the push
about 1.12x faster (docs/measurements.md, thirty-eighth session).

`reference(value)` copies the value once into the calling kernel's frame and hands on a
pointer to it (a `types.CPointer`); `referent(ref)` in the kernel that takes it reads the
value back. Holding the value still is the caller's part: it is read as it was when
`reference` copied it, so a reference is made where the value stays the same for as long as
it is used (`_contact_run`: the scene's tables, the System, the buffers, before its loop).
The arrays' contents are not part of the value: a kernel writes into them as before.
"""

from __future__ import annotations

from numba.core import cgutils, types
from numba.extending import intrinsic


@intrinsic
def reference(typingctx, value):
    """A pointer to a copy of value in the calling kernel's frame (valid for that call)."""
    sig = types.CPointer(value)(value)

    def codegen(context, builder, signature, args):
        model = context.data_model_manager[signature.args[0]]
        slot = cgutils.alloca_once_value(builder, model.as_data(builder, args[0]))
        return builder.bitcast(slot, context.get_value_type(signature.return_type))

    return sig, codegen


@intrinsic
def referent(typingctx, ref):
    """The value `ref` (a `reference`) points at."""
    sig = ref.dtype(ref)

    def codegen(context, builder, signature, args):
        model = context.data_model_manager[signature.return_type]
        value = builder.load(builder.bitcast(args[0], model.get_data_type().as_pointer()))
        return model.from_data(builder, value)

    return sig, codegen

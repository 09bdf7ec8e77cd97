"""Values passed to a compiled kernel by reference: one pointer where numba would pass hundreds.

numba passes a tuple flat: every array in it as its 7 to 11 machine words (meminfo, parent,
size, itemsize, data, shape, strides), each copied onto the stack at every call. The warm
contact steps take the scene's tables, the System, the contact buffers and their own
scratch (`models.stepper.SpatialWarm`, about 40 arrays): about 700 words a call, once a step.
On box_push_3d's push, perf put 6.7% of the step's time on the `push` instructions of
`models.rollout._contact_run`'s calls (docs/measurements.md, thirty-eighth session).

`reference(value)` copies the value once into the caller's frame and hands on a pointer to it
(a `types.CPointer`); `referent(ref, "name")` in the kernel that takes it reads the value
back. A pointer alone is not enough: read through a plain pointer, the value's words are loaded
at the kernel's entry and spilled to its own stack, the same copy on the other side of the
call (the thirtieth session measured no gain that way). So `referent` tells LLVM what holds:
the memory it points at is there for the whole call (its argument `dereferenceable` by the
value's size, `nonnull`), read through nothing else (`noalias`) and never written while the
kernel runs (the load `!invariant.load`). LLVM then reads each word where it is used.

Holding that is the caller's part: the value is copied where `reference` is called and read
as it was then, so a reference is made where the value stays the same for as long as it is
used (`_contact_run`: the scene's tables, the System, the buffers, before its loop). The arrays'
contents are not part of the value: a kernel writes into them as before.

`referent` finds its argument by numba's name for it ("arg." and the parameter's name); where
numba names arguments otherwise, the value is read without the attributes (the same results,
slower: tests/test_reference.py checks that they are there).
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
def referent(typingctx, ref, name):
    """The value `ref` (a `reference`, the kernel's parameter called `name`, a literal string)
    points at, read as unchanging memory that nothing else reads or writes during the call."""
    if not isinstance(name, types.StringLiteral):
        return None  # (numba types the call again with the literal)
    argument = "arg." + name.literal_value
    sig = ref.dtype(ref, name)

    def codegen(context, builder, signature, args):
        model = context.data_model_manager[signature.return_type]
        data = model.get_data_type()
        for a in builder.function.args:
            if a.name == argument:
                a.attributes.dereferenceable = context.get_abi_sizeof(data)
                a.add_attribute("noalias")
                a.add_attribute("nonnull")
        value = builder.load(builder.bitcast(args[0], data.as_pointer()))
        value.set_metadata("invariant.load", builder.module.add_metadata([]))
        return model.from_data(builder, value)

    return sig, codegen

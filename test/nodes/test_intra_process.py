"""Taps and their dispatcher (``maglev_ros.nodes.intra_process``), without ROS traffic.

A tap hands a publisher's messages to its listeners in the publisher's thread;
with a :class:`TapDispatcher` installed for the context, in the dispatcher's
thread instead, in the order they were given across all taps of the context
(a command given after its samples still reaches a recorder after them), and
closing the dispatcher hands on what is queued.
"""

import threading

from maglev_ros.nodes import intra_process


class _Context:  # taps and dispatchers are kept per context object
    pass


def test_taps_deliver_in_the_publishers_thread_without_a_dispatcher():
    ctx = _Context()
    got = []
    tap = intra_process.tap(ctx, '/a')
    assert intra_process.tap(ctx, '/a') is tap and intra_process.tap(_Context(), '/a') is not tap
    tap.connect(lambda msgs: got.append((threading.current_thread(), msgs)), 'test')
    tap.deliver([b'1', b'2'])
    assert got == [(threading.current_thread(), [b'1', b'2'])]


def test_a_dispatcher_hands_on_every_tap_in_order_in_its_thread():
    ctx, other = _Context(), _Context()
    samples, commands, elsewhere = (intra_process.tap(c, t) for c, t in
                                    ((ctx, '/s'), (ctx, '/c'), (other, '/s')))  # fmt: skip
    got, threads = [], set()
    release = threading.Event()

    def listener(name):
        def on_messages(msgs):
            thread = threading.current_thread().name
            if thread == 'test-taps':  # the first waits: the rest queue up behind it
                release.wait(10.0)
            threads.add(thread)
            got.append((name, msgs))

        return on_messages

    samples.connect(listener('samples'), 'test')
    commands.connect(listener('commands'), 'test')
    elsewhere.connect(listener('elsewhere'), 'test')
    dispatcher = intra_process.TapDispatcher('test-taps')
    intra_process.dispatch_taps(ctx, dispatcher)
    try:
        for k in range(50):  # a read's samples, then the command that answers it
            samples.deliver([b's%d' % k])
            commands.deliver([b'c%d' % k])
        elsewhere.deliver([b'x'])  # another context: its publisher's thread, at once
        assert got == [('elsewhere', [b'x'])]
        assert dispatcher.backlog >= 99  # queued behind the first, which waits
        release.set()
    finally:
        intra_process.dispatch_taps(ctx, None)
        dispatcher.close()
    expected = [('elsewhere', [b'x'])]
    for k in range(50):
        expected += [('samples', [b's%d' % k]), ('commands', [b'c%d' % k])]
    assert got == expected  # all handed on at close, in the order given
    assert threads == {threading.current_thread().name, 'test-taps'}
    samples.deliver([b'after'])  # no dispatcher any more: the publisher's thread
    assert got[-1] == ('samples', [b'after'])

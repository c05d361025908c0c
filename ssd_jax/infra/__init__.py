"""The plumbing every part shares and the method does not need to be read: the command
line (`cli`), errors, logging, runtime and device settings, processes (`distributed`),
checkpoints (orbax), and the patterns that read other libraries' messages
(`library_text`)."""

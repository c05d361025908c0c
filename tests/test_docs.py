"""The user guide and the reference pages: their links resolve and CI runs the README's tests."""

import functools
import pathlib
import re
import unicodedata

ROOT = pathlib.Path(__file__).resolve().parent.parent
PAGES = [ROOT / 'README.md', *sorted((ROOT / 'docs').rglob('*.md')),
         ROOT / 'configs' / 'experiments' / 'README.md',
         *sorted((ROOT / 'ssd_jax' / 'weights').glob('*/MODEL_CARD.md'))]
# [text](target): relative targets only; web links and images of plots written by runs are not
# the repository's to check.
LINK = re.compile(r'\[[^\]]*\]\(([^)\s]+)\)')


def slug(heading: str) -> str:
  """GitHub's anchor of a Markdown heading: lower case, punctuation dropped, spaces to '-'."""
  text = heading.strip().lower()
  kept = ''.join(c for c in text if c in ' -_' or unicodedata.category(c)[0] in 'LN')
  return kept.replace(' ', '-')


@functools.cache   # a page is read once, however many links point into it
def anchors(page: pathlib.Path) -> frozenset[str]:
  in_code = False
  found = set()
  for line in page.read_text().splitlines():
    if line.startswith('```'):
      in_code = not in_code
    elif not in_code and line.startswith('#'):
      found.add(slug(line.lstrip('#')))
  return frozenset(found)


def test_slug_follows_github():
  assert slug(' CF weights and the learning rate') == 'cf-weights-and-the-learning-rate'
  assert slug('Descriptor matching (Table III)') == 'descriptor-matching-table-iii'
  assert slug('The main job\'s Table I') == 'the-main-jobs-table-i'


def test_every_relative_link_and_anchor_resolves():
  broken = []
  for page in PAGES:
    for target in LINK.findall(page.read_text()):
      if re.match(r'[a-z]+:', target):
        continue
      path, _, anchor = target.partition('#')
      dest = (page.parent / path).resolve() if path else page
      if not dest.exists():
        broken.append(f'{page.relative_to(ROOT)}: {target} (no such file)')
      elif anchor and dest.suffix == '.md' and anchor not in anchors(dest):
        broken.append(f'{page.relative_to(ROOT)}: {target} (no such heading)')
  assert not broken, '\n'.join(broken)


def test_every_config_and_command_a_page_names_exists():
  """The configs (`configs/...py[:arg]`) and commands (`python -m experiments.x`) named by
  the pages, the configs' docstrings and the experiments' own: a renamed file fails here."""
  texts = [page.read_text() for page in PAGES]
  texts += [p.read_text() for p in sorted((ROOT / 'configs').rglob('*.py'))]
  texts += [p.read_text() for p in sorted((ROOT / 'experiments').rglob('*.py'))]
  missing = set()
  for text in texts:
    for path in re.findall(r'\bconfigs/[a-z_/0-9]+\.py', text):
      if not (ROOT / path).exists():
        missing.add(path)
    for module in re.findall(r'python -m experiments\.([a-z_0-9.]+[a-z_0-9])', text):
      if not (ROOT / 'experiments' / f'{module.replace(".", "/")}.py').exists():
        missing.add(f'experiments.{module}')
  assert not missing, sorted(missing)


def test_ci_runs_exactly_the_readme_test_command():
  readme = (ROOT / 'README.md').read_text().splitlines()
  block = readme[readme.index('```bash') + 1:]
  commands = block[:block.index('```')]
  assert len(commands) == 2, commands
  ci = [line for line in (ROOT / '.ci' / 'run').read_text().splitlines()
        if line.strip() and not line.startswith('#')]
  assert ci[-1] == commands[1]


def test_readme_is_a_guide_of_at_most_200_lines():
  assert len((ROOT / 'README.md').read_text().splitlines()) <= 200
